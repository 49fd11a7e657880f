//! The `parallel-robot` command line: inverse and forward dynamics of the
//! paper's parallel robot along its circle, the speed-against-error study,
//! and flexdyn's `export` and `eval` for the robot scenes compiled in here
//! (what the CasADi validation calls).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use flexdyn::cli;
use flexdyn_parallel_robot as robot_crate;

/// The spatial parallel robot of the paper on flexdyn's generated equations.
#[derive(Parser)]
#[command(name = "parallel-robot", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Inverse dynamics of the parallel robot along a circle of the platform
    /// centre (the paper's Eq. 23 by default): the actuator torques, through
    /// the runtime's real-time path for the rigid robot; for a flexible scene
    /// by servo constraints on the platform with the elastic coordinates
    /// integrated (generalized-alpha, one step per --dt).
    Inverse {
        /// Scene file of the robot (`examples/parallel-robot/scenes/parallel_robot_rigid.toml`
        /// or a flexible variant, e.g. `.../parallel_robot_flexible.toml`).
        #[arg(long)]
        scene: PathBuf,
        /// Angular rate of the circle, rad/s.
        #[arg(long, default_value_t = 2.0, allow_negative_numbers = true)]
        omega: f64,
        /// Duration, s.
        #[arg(long, default_value_t = 5.0, allow_negative_numbers = true)]
        duration: f64,
        /// Output step, s.
        #[arg(long, default_value_t = 0.005, allow_negative_numbers = true)]
        dt: f64,
        /// Largest number of steps of --dt in --duration (refused before the
        /// run).
        #[arg(long, default_value_t = flexdyn::steps::MAX_STEPS)]
        max_steps: u64,
        /// Radius of the circle, m.
        #[arg(long, default_value_t = 0.1, allow_negative_numbers = true)]
        radius: f64,
        /// Centre of the circle as x,y,z in m.
        #[arg(long, default_value = "0,0,0.7", allow_negative_numbers = true)]
        center: String,
        /// CSV output: t, tau_1..3 (N m), px, py, pz (m), vx, vy, vz (m/s), th11, th21, th31 (rad);
        /// for flexible scenes px..vz are the prescribed circle and dx, dy, dz (m) the
        /// platform's deviation from it (servo-constraint accuracy).
        #[arg(long)]
        csv: Option<PathBuf>,
        /// Plot of the three torques against time (.png or .svg).
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Also write every output step's full state (q, qd, t) as JSON in
        /// the `flexdyn eval` input format: the scene's working states for the
        /// CasADi validation (`scenes/<scene>.states.json`).
        #[arg(long, value_name = "FILE")]
        states: Option<PathBuf>,
        /// No progress bar and no summary.
        #[arg(long)]
        quiet: bool,
    },
    /// Forward dynamics of the parallel robot under actuator torques read from
    /// a CSV (columns t, tau_1, tau_2, tau_3, linearly interpolated), starting
    /// from the consistent state at the first row's platform position px, py,
    /// pz and velocity vx, vy, vz (zero when those columns are absent).
    Simulate {
        /// Scene file of the robot.
        #[arg(long)]
        scene: PathBuf,
        /// Torques to apply (e.g. the CSV written by `parallel-robot inverse`).
        #[arg(long)]
        torques: PathBuf,
        /// Output CSV: t, px, py, pz (m), th11, th21, th31 (rad), phi_max (constraint residual),
        /// tau_1..3 (applied torques, N m), dx, dy, dz (m, deviation from the torque table's
        /// px, py, pz: the path the torques were computed for).
        #[arg(long)]
        csv: Option<PathBuf>,
        /// Plot (.png or .svg) of the platform position against time; for a
        /// flexible scene, of its deviation dx, dy, dz in mm.
        #[arg(long)]
        plot: Option<PathBuf>,
        /// Add a joint-space PD loop on the actuated joints around the torque
        /// table's angles th11, th21, th31, with the scene's gains (parameters
        /// `pd_kp`, `pd_kd`) unless --kp/--kd are given.
        #[arg(long)]
        pd: bool,
        /// Proportional gain of the PD loop, N m/rad (implies --pd).
        #[arg(long, allow_negative_numbers = true)]
        kp: Option<f64>,
        /// Derivative gain of the PD loop, N m s/rad (implies --pd).
        #[arg(long, allow_negative_numbers = true)]
        kd: Option<f64>,
        /// Integration step, s.
        #[arg(long, default_value_t = 0.001, allow_negative_numbers = true)]
        dt: f64,
        /// Largest number of steps of --dt in --duration (refused before the
        /// run).
        #[arg(long, default_value_t = flexdyn::steps::MAX_STEPS)]
        max_steps: u64,
        /// Output step, s (a multiple of --dt).
        #[arg(long, default_value_t = 0.005, allow_negative_numbers = true)]
        output_dt: f64,
        /// Duration, s (default: up to the last torque sample).
        #[arg(long, allow_negative_numbers = true)]
        duration: Option<f64>,
        /// Integrator: rk4, semi-implicit or gen-alpha (default: rk4 for the
        /// rigid robot, gen-alpha for flexible scenes).
        #[arg(long)]
        integrator: Option<robot_crate::robot::Scheme>,
        /// No progress bar and no summary.
        #[arg(long)]
        quiet: bool,
    },
    /// Measure speed against error of the robot's model variants and
    /// integrators on this machine and write the crate's docs/performance.md, its CSV and
    /// its Pareto plots (a few minutes; --quick for a small version).
    Report {
        /// The Markdown page; the CSV and plots go to a folder of the same
        /// name without the extension.
        #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/docs/performance.md"))]
        out: PathBuf,
        /// A small study (three variants, short runs, no repetition), for a
        /// quick look or a test.
        #[arg(long)]
        quick: bool,
        /// Timed repetitions of each run (default 3; 1 with --quick).
        #[arg(long)]
        repeats: Option<usize>,
        /// Directory of the scene files.
        #[arg(long, default_value = concat!(env!("CARGO_MANIFEST_DIR"), "/scenes"))]
        scenes: PathBuf,
        /// No progress bar and no summary.
        #[arg(long)]
        quiet: bool,
    },
    Export(cli::export::Args),
    Eval(cli::eval::Args),
}

fn main() -> ExitCode {
    let result = match Cli::parse().command {
        Command::Export(args) => cli::export::run(&args),
        Command::Report {
            out,
            quick,
            repeats,
            scenes,
            quiet,
        } => report(&out, quick, repeats, &scenes, quiet),
        Command::Eval(args) => cli::eval::run(&args, &robot_crate::COMPILED_SCENES),
        Command::Inverse {
            scene,
            omega,
            duration,
            dt,
            max_steps,
            radius,
            center,
            csv,
            plot,
            states,
            quiet,
        } => parse_center(&center).and_then(|center| {
            let circle = robot_crate::robot::Circle {
                omega,
                radius,
                center,
            };
            inverse(
                &scene,
                &circle,
                (duration, dt, max_steps),
                &InverseOutputs { csv, plot, states },
                quiet,
            )
        }),
        Command::Simulate {
            scene,
            torques,
            csv,
            plot,
            pd,
            kp,
            kd,
            dt,
            max_steps,
            output_dt,
            duration,
            integrator,
            quiet,
        } => simulate(&SimulateArgs {
            scene,
            torques,
            csv,
            plot,
            pd: pd || kp.is_some() || kd.is_some(),
            kp,
            kd,
            dt,
            max_steps,
            output_dt,
            duration,
            integrator,
            quiet,
        }),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn parse_center(text: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = text
        .split(',')
        .map(|x| x.trim().parse::<f64>().ok().filter(|x| x.is_finite()))
        .collect::<Option<Vec<f64>>>()
        .ok_or_else(|| format!("--center must be three numbers x,y,z, got `{text}`"))?;
    <[f64; 3]>::try_from(v)
        .map_err(|_| format!("--center must be three numbers x,y,z, got `{text}`"))
}

/// The files `parallel-robot inverse` writes.
struct InverseOutputs {
    csv: Option<PathBuf>,
    plot: Option<PathBuf>,
    states: Option<PathBuf>,
}

/// `(duration, dt, max_steps)`: the run's span, step and step limit. The
/// rows are streamed to the files as they are computed (the plot from a
/// bounded copy of them): a run of any length needs the same memory.
fn inverse(
    scene: &Path,
    circle: &robot_crate::robot::Circle,
    (duration, dt, max_steps): (f64, f64, u64),
    files: &InverseOutputs,
    quiet: bool,
) -> Result<(), String> {
    use flexdyn::plot::{Decimated, PLOT_ROWS};
    use flexdyn::table::{CsvWriter, OutputFiles, TextWriter};
    use robot_crate::robot::{each_output_time, stream_inverse_rows};
    let (parsed, geometry) = robot_scene(scene, "inverse")?;
    if !(circle.omega.is_finite() && circle.radius.is_finite() && circle.radius >= 0.0) {
        return Err("--omega must be finite and --radius finite and non-negative".into());
    }
    let times = each_output_time(duration, dt, max_steps)?;
    check_outputs([&files.csv, &files.states, &files.plot])?;
    let flexible = parsed.nq() > 12;
    let mut columns = vec![
        "t", "tau_1", "tau_2", "tau_3", "px", "py", "pz", "vx", "vy", "vz", "th11", "th21", "th31",
    ];
    if flexible {
        columns.extend(["dx", "dy", "dz"]);
    }
    let columns: Vec<String> = columns.into_iter().map(String::from).collect();
    let mut outputs = OutputFiles::default();
    let mut csv = files
        .csv
        .as_ref()
        .map(|path| CsvWriter::create(&mut outputs, path, &columns))
        .transpose()?;
    // The `flexdyn eval` input format, `{"states":[{...},...]}`, a state at a time.
    let mut states = files
        .states
        .as_ref()
        .map(|path| {
            let mut states = TextWriter::create(&mut outputs, path)?;
            states.write("{\"states\":[", None)?;
            Ok::<_, String>(states)
        })
        .transpose()?;
    let mut separator = "";
    // The plotted torques (after `t`) of a bounded copy of the rows.
    let mut kept = files.plot.as_ref().map(|_| Decimated::new(PLOT_ROWS));
    let mut peak = [0.0; 3];
    let mut row = Vec::with_capacity(columns.len());
    let mut progress =
        flexdyn::progress::Progress::new(times.len() as u64, "inverse dynamics", quiet);
    robot_crate::with_robot_model!(parsed.name.as_str(), model => {
        stream_inverse_rows(&model, &geometry, circle, times.clone(), &mut |s| {
            // Flexible scenes: the prescribed path, and the platform's deviation from it.
            let [p, v, _] = if flexible {
                circle.at(s.t)
            } else {
                [s.p, s.v, [0.0; 3]]
            };
            if let Some(csv) = &mut csv {
                row.clear();
                row.extend([
                    s.t, s.tau[0], s.tau[1], s.tau[2], p[0], p[1], p[2], v[0], v[1], v[2],
                    s.th[0], s.th[1], s.th[2],
                ]);
                if flexible {
                    row.extend((0..3).map(|k| s.p[k] - p[k]));
                }
                csv.row(&row)?;
            }
            if let Some(states) = &mut states {
                let state = serde_json::json!({ "t": s.t, "q": s.q, "qd": s.qd });
                states.write(separator, Some(s.t))?;
                states.write(&state.to_string(), Some(s.t))?;
                separator = ",";
            }
            if let Some(kept) = &mut kept {
                kept.push(&[s.t, s.tau[0], s.tau[1], s.tau[2]]);
            }
            for (peak, tau) in peak.iter_mut().zip(s.tau) {
                *peak = f64::max(*peak, tau.abs());
            }
            progress.inc();
            Ok(())
        })
    })
    .ok_or_else(|| format!("scene `{}` is not a robot scene", parsed.name))??;
    progress.finish();
    if let Some(csv) = csv {
        csv.finish()?;
    }
    if let Some(mut states) = states {
        states.write("]}\n", None)?;
        states.finish()?;
    }
    if let (Some(path), Some(kept)) = (&files.plot, kept) {
        let rows = kept.rows();
        let series: Vec<flexdyn::plot::Series> = (1..=3)
            .map(|i| flexdyn::plot::Series {
                label: ["tau_1", "tau_2", "tau_3"][i - 1],
                points: rows.iter().map(|r| (r[0], r[i])).collect(),
            })
            .collect();
        let title = format!(
            "Driving torques, {} (omega = {} rad/s)",
            parsed.name, circle.omega
        );
        outputs.write(path, |tmp| {
            flexdyn::plot::line_plot(
                tmp,
                &flexdyn::plot::Labels {
                    title: &title,
                    x: "t (s)",
                    y: "torque (N m)",
                },
                &series,
            )
        })?;
    }
    outputs.commit()?;
    if !quiet {
        for (i, peak) in peak.iter().enumerate() {
            println!("chain {}: max |tau_{}| = {:.4} N m", i + 1, i + 1, peak);
        }
    }
    Ok(())
}

/// Each output file given can be written (checked before the run).
fn check_outputs<const N: usize>(paths: [&Option<PathBuf>; N]) -> Result<(), String> {
    paths
        .into_iter()
        .flatten()
        .try_for_each(|path| flexdyn::table::check_output(path))
}

struct SimulateArgs {
    scene: PathBuf,
    torques: PathBuf,
    csv: Option<PathBuf>,
    plot: Option<PathBuf>,
    pd: bool,
    kp: Option<f64>,
    kd: Option<f64>,
    dt: f64,
    max_steps: u64,
    output_dt: f64,
    duration: Option<f64>,
    integrator: Option<robot_crate::robot::Scheme>,
    quiet: bool,
}

/// The rows are streamed to the CSV as they are computed (the plot from a
/// bounded copy of them): a run of any length needs the same memory.
fn simulate(a: &SimulateArgs) -> Result<(), String> {
    use flexdyn::plot::{Decimated, PLOT_ROWS};
    use flexdyn::steps::{count, per_output, Last};
    use flexdyn::table::{CsvWriter, OutputFiles};
    use robot_crate::robot::{stream_simulate_rows, PdSettings, Scheme, TorqueTable};
    let (parsed, geometry) = robot_scene(&a.scene, "simulate")?;
    let flexible = parsed.nq() > 12;
    let table = flexdyn::table::Table::read(&a.torques)?;
    let in_table = |e: String| format!("{}: {e}", a.torques.display());
    let torques = TorqueTable::from_table(&table).map_err(in_table)?;
    let first = |name: &str, default: Option<f64>| -> Result<f64, String> {
        match table.column(name) {
            Ok(c) => Ok(c[0]),
            Err(e) => default.ok_or_else(|| format!("{}: {e}", a.torques.display())),
        }
    };
    let p = [first("px", None)?, first("py", None)?, first("pz", None)?];
    let v = [
        first("vx", Some(0.0))?,
        first("vy", Some(0.0))?,
        first("vz", Some(0.0))?,
    ];
    // The path the torques were computed for, to measure the deviation from.
    let path = TorqueTable::from_columns(&table, ["px", "py", "pz"]).map_err(in_table)?;
    let pd = if a.pd {
        let gain = |name: &str, given: Option<f64>, option: &str| {
            given
                .or_else(|| parsed.parameters.get(name).copied())
                .ok_or_else(|| {
                    format!(
                        "--pd: scene `{}` declares no parameter `{name}` (PD gain); give {option}",
                        parsed.name
                    )
                })
        };
        let reference = TorqueTable::from_columns(&table, ["th11", "th21", "th31"])
            .map_err(|e| in_table(format!("{e} (--pd needs the reference joint angles)")))?;
        Some(PdSettings {
            kp: gain("pd_kp", a.kp, "--kp")?,
            kd: gain("pd_kd", a.kd, "--kd")?,
            reference,
        })
    } else {
        None
    };
    let scheme = a.integrator.unwrap_or(if flexible {
        Scheme::GeneralizedAlpha
    } else {
        Scheme::Rk4
    });
    let (t0, t1) = torques.span();
    let duration = a.duration.unwrap_or(t1 - t0);
    let steps = usize::try_from(count(duration, a.dt, Last::Within, a.max_steps)?)
        .map_err(|_| "too many steps for this machine".to_string())?;
    let every = per_output("--output-dt", a.output_dt, "--dt", a.dt)? as usize;
    check_outputs([&a.csv, &a.plot])?;
    let deviation = |r: &robot_crate::robot::SimRow| {
        let want = path.at(r.t);
        [r.p[0] - want[0], r.p[1] - want[1], r.p[2] - want[2]]
    };
    let columns: Vec<String> = [
        "t", "px", "py", "pz", "th11", "th21", "th31", "phi_max", "tau_1", "tau_2", "tau_3", "dx",
        "dy", "dz",
    ]
    .map(String::from)
    .into();
    let mut outputs = OutputFiles::default();
    let mut csv = a
        .csv
        .as_ref()
        .map(|path| CsvWriter::create(&mut outputs, path, &columns))
        .transpose()?;
    // The plotted values (after `t`) of a bounded copy of the rows: the
    // deviation in mm for a flexible scene, the position otherwise.
    let (labels, scale) = match flexible {
        true => (["dx", "dy", "dz"], 1e3),
        false => (["px", "py", "pz"], 1.0),
    };
    let mut kept = a.plot.as_ref().map(|_| Decimated::new(PLOT_ROWS));
    let (mut peak, mut last) = ([0.0; 3], 0.0);
    let mut progress = flexdyn::progress::Progress::new(steps as u64, "forward dynamics", a.quiet);
    robot_crate::with_robot_model!(parsed.name.as_str(), model => stream_simulate_rows(
        &model,
        &geometry,
        scheme,
        (t0, p, v),
        &torques,
        pd.as_ref(),
        (a.dt, steps, every),
        &mut || progress.inc(),
        &mut |r| {
            let d = deviation(&r);
            if let Some(csv) = &mut csv {
                csv.row(&[
                    r.t, r.p[0], r.p[1], r.p[2], r.th[0], r.th[1], r.th[2], r.phi_max, r.tau[0],
                    r.tau[1], r.tau[2], d[0], d[1], d[2],
                ])?;
            }
            if let Some(kept) = &mut kept {
                let plotted = if flexible { d } else { r.p };
                kept.push(&[r.t, scale * plotted[0], scale * plotted[1], scale * plotted[2]]);
            }
            for (peak, d) in peak.iter_mut().zip(d) {
                *peak = f64::max(*peak, d.abs());
            }
            last = r.t;
            Ok(())
        },
    ))
    .ok_or_else(|| format!("scene `{}` is not a robot scene", parsed.name))??;
    progress.finish();
    if let Some(csv) = csv {
        csv.finish()?;
    }
    if let (Some(plot), Some(kept)) = (&a.plot, kept) {
        let (title, y) = if flexible {
            (
                format!(
                    "Platform deviation from the torques' path, {}{}",
                    parsed.name,
                    if pd.is_some() { " (with PD)" } else { "" }
                ),
                "deviation (mm)",
            )
        } else {
            (
                "Platform position under the given torques".to_string(),
                "position (m)",
            )
        };
        let rows = kept.rows();
        let series: Vec<flexdyn::plot::Series> = labels
            .iter()
            .enumerate()
            .map(|(k, label)| flexdyn::plot::Series {
                label,
                points: rows.iter().map(|r| (r[0], r[k + 1])).collect(),
            })
            .collect();
        outputs.write(plot, |tmp| {
            flexdyn::plot::line_plot(
                tmp,
                &flexdyn::plot::Labels {
                    title: &title,
                    x: "t (s)",
                    y,
                },
                &series,
            )
        })?;
    }
    outputs.commit()?;
    if !a.quiet {
        println!(
            "simulated {:.3} s in {} steps of {} s",
            last - t0,
            steps,
            a.dt
        );
        println!(
            "max |dx| = {:.4} mm, max |dy| = {:.4} mm, max |dz| = {:.4} mm",
            1e3 * peak[0],
            1e3 * peak[1],
            1e3 * peak[2]
        );
    }
    Ok(())
}

fn report(
    out: &Path,
    quick: bool,
    repeats: Option<usize>,
    scenes: &Path,
    quiet: bool,
) -> Result<(), String> {
    use robot_crate::report::{op_counts, run, run_count, Files, Settings, Study};
    let mut settings = if quick {
        Settings::quick()
    } else {
        Settings::full()
    };
    if let Some(r) = repeats {
        if r == 0 || r > 100 {
            return Err(format!("--repeats must be between 1 and 100, got {r}"));
        }
        settings.repeats = r;
    }
    let ops = op_counts(scenes, &settings.variants)?;
    let mut progress =
        flexdyn::progress::Progress::new(run_count(&settings) as u64, "report", quiet);
    let study = Study::new(settings, scenes)?;
    let results = run(&study, &mut |_| progress.inc())?;
    progress.finish();
    let files = Files::new(out);
    robot_crate::report::write(&results, &ops, &files)?;
    if !quiet {
        println!(
            "{} runs in {:.0} s; wrote {} and {}/",
            results.forward.len() + results.inverse.len() + 4,
            results.elapsed,
            files.page.display(),
            files.dir.display()
        );
    }
    Ok(())
}

/// Load a robot scene the robot commands support, with its geometry.
fn robot_scene(
    scene: &Path,
    command: &str,
) -> Result<(flexdyn::codegen::Model, robot_crate::robot::Geometry), String> {
    let parsed = flexdyn::codegen::Model::load(scene).map_err(|e| e.to_string())?;
    if !robot_crate::robot::ROBOT_SCENES.contains(&parsed.name.as_str()) {
        return Err(format!(
            "`{command}` drives the parallel robot; scene `{}` is not one (try examples/parallel-robot/scenes/parallel_robot_rigid.toml; \
             robot scenes: {})",
            parsed.name,
            robot_crate::robot::ROBOT_SCENES.join(", ")
        ));
    }
    let geometry = robot_crate::robot::Geometry::from_parameters(&parsed.parameters)?;
    Ok((parsed, geometry))
}
