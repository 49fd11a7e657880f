//! The `flexdyn` command line.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use clap::{Parser, Subcommand};
use flexdyn::table::write_atomic;

/// Exact, allocation-free equations of motion for rigid and flexible
/// multibody systems, generated from scene files.
#[derive(Parser)]
#[command(name = "flexdyn", version, about, long_about = None)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Generate the Rust module of one or more scenes into a directory.
    ///
    /// Writes `<scene name>.rs` per scene, only when its content changed, and
    /// nothing at all if any scene has an error.
    Generate {
        /// Scene file(s) to generate.
        #[arg(long, required_unless_present = "all")]
        scene: Vec<PathBuf>,
        /// Generate every scene in `scenes/`.
        #[arg(long)]
        all: bool,
        /// Output directory.
        #[arg(long, default_value = "generated")]
        out: PathBuf,
        /// Print nothing but errors.
        #[arg(long)]
        quiet: bool,
    },
    /// Export a scene's symbolic inputs (energies, constraints, actuators) as
    /// JSON in the documented `flexdyn-scene-export/1` format.
    Export {
        /// Scene file.
        #[arg(long)]
        scene: PathBuf,
        /// Output file.
        #[arg(long)]
        out: PathBuf,
    },
    /// Evaluate every generated term of a scene at states read from
    /// JSON (`{"states": [{"q": [..], "qd": [..], "t": 0.0}]}`) and write
    /// them as JSON.
    Eval {
        /// Scene file: a compiled-in scene is evaluated by its compiled
        /// module, any other by the interpreter (bitwise the same numbers).
        #[arg(long)]
        scene: PathBuf,
        /// States file.
        #[arg(long)]
        states: PathBuf,
        /// Output file (standard output when absent).
        #[arg(long)]
        out: Option<PathBuf>,
        /// Test-only hook: evaluate the build of the scene with one emitted
        /// coefficient deliberately wrong (pendulum and parallel_robot_rigid).
        #[arg(long, hide = true)]
        perturbed: bool,
    },
    /// Inverse dynamics of the parallel robot along a circle of the platform
    /// centre (the paper's Eq. 23 by default): the actuator torques, through
    /// the runtime's real-time path for the rigid robot; for a flexible scene
    /// by servo constraints on the platform with the elastic coordinates
    /// integrated (generalized-alpha, one step per --dt).
    Inverse {
        /// Scene file of the robot (`scenes/parallel_robot_rigid.toml` or a
        /// flexible variant, e.g. `scenes/parallel_robot_flexible.toml`).
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
        /// Torques to apply (e.g. the CSV written by `flexdyn inverse`).
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
        /// Output step, s (a multiple of --dt).
        #[arg(long, default_value_t = 0.005, allow_negative_numbers = true)]
        output_dt: f64,
        /// Duration, s (default: up to the last torque sample).
        #[arg(long, allow_negative_numbers = true)]
        duration: Option<f64>,
        /// Integrator: rk4, semi-implicit or gen-alpha (default: rk4 for the
        /// rigid robot, gen-alpha for flexible scenes).
        #[arg(long)]
        integrator: Option<flexdyn::robot::Scheme>,
        /// No progress bar and no summary.
        #[arg(long)]
        quiet: bool,
    },
    /// Measure speed against error of the robot's model variants and
    /// integrators on this machine and write docs/performance.md, its CSV and
    /// its Pareto plots (a few minutes; --quick for a small version).
    Report {
        /// The Markdown page; the CSV and plots go to a folder of the same
        /// name without the extension.
        #[arg(long, default_value = "docs/performance.md")]
        out: PathBuf,
        /// A small study (three variants, short runs, no repetition), for a
        /// quick look or a test.
        #[arg(long)]
        quick: bool,
        /// Timed repetitions of each run (default 3; 1 with --quick).
        #[arg(long)]
        repeats: Option<usize>,
        /// Directory of the scene files.
        #[arg(long, default_value = "scenes")]
        scenes: PathBuf,
        /// No progress bar and no summary.
        #[arg(long)]
        quiet: bool,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Generate {
            scene,
            all,
            out,
            quiet,
        } => {
            let mut builder = flexdyn::codegen::Builder::new().out_dir(&out);
            for s in scene {
                builder = builder.scene(s);
            }
            if all {
                builder = builder.scenes_in("scenes");
            }
            match builder.generate() {
                Ok(report) => {
                    if !quiet {
                        for s in &report.scenes {
                            println!("{s}");
                        }
                        println!(
                            "{} file(s) written to {} ({} unchanged)",
                            report.written.len(),
                            out.display(),
                            report.scenes.len().saturating_sub(report.written.len())
                        );
                    }
                    Ok(())
                }
                Err(e) => Err(e.to_string()),
            }
        }
        Command::Export { scene, out } => export(&scene, &out),
        Command::Report {
            out,
            quick,
            repeats,
            scenes,
            quiet,
        } => report(&out, quick, repeats, &scenes, quiet),
        Command::Eval {
            scene,
            states,
            out,
            perturbed,
        } => eval(&scene, &states, out.as_deref(), perturbed),
        Command::Inverse {
            scene,
            omega,
            duration,
            dt,
            radius,
            center,
            csv,
            plot,
            states,
            quiet,
        } => parse_center(&center).and_then(|center| {
            let circle = flexdyn::robot::Circle {
                omega,
                radius,
                center,
            };
            inverse(
                &scene,
                &circle,
                duration,
                dt,
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

fn export(scene: &Path, out: &Path) -> Result<(), String> {
    let model = flexdyn::codegen::model::Model::load(scene).map_err(|e| e.to_string())?;
    write_atomic(out, &flexdyn::codegen::export::export_json(&model))
}

fn eval(scene: &Path, states: &Path, out: Option<&Path>, perturbed: bool) -> Result<(), String> {
    use flexdyn::eval::{check_state, evaluate, States};
    let parsed = flexdyn::codegen::model::Model::load(scene).map_err(|e| e.to_string())?;
    let lookup = if perturbed {
        flexdyn::perturbed_scenes::model
    } else {
        flexdyn::scenes::model
    };
    // A scene not compiled in is interpreted: the same numbers, bitwise.
    let interpreted = match lookup(&parsed.name) {
        None if !perturbed => Some(flexdyn::interpreted::InterpretedModel::load(scene)?),
        _ => None,
    };
    let fresh = |name: &str| -> Result<Box<dyn flexdyn::dynamic::DynModel>, String> {
        match (lookup(name), &interpreted) {
            (Some(m), _) => Ok(m),
            (None, Some(i)) => Ok(Box::new(i.clone())),
            (None, None) => Err(format!(
                "scene `{name}` has no perturbed build (those are: {})",
                flexdyn::perturbed_scenes::SCENES.join(", ")
            )),
        }
    };
    let mut model = fresh(&parsed.name)?;
    let text = std::fs::read_to_string(states)
        .map_err(|e| format!("cannot read {}: {e}", states.display()))?;
    let input: States =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", states.display()))?;
    let mut results = Vec::with_capacity(input.states.len());
    for (k, s) in input.states.iter().enumerate() {
        check_state(model.as_ref(), s, k)?;
        if !s.params.is_empty() {
            // Parameters apply to this state only: start from the defaults.
            model = fresh(&parsed.name)?;
        }
        results.push(evaluate(model.as_mut(), s).map_err(|e| format!("state {k}: {e}"))?);
    }
    let json = serde_json::json!({ "scene": parsed.name, "results": results });
    let text = serde_json::to_string(&json).map_err(|e| e.to_string())?;
    match out {
        Some(path) => write_atomic(path, &text),
        None => {
            println!("{text}");
            Ok(())
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

/// The files `flexdyn inverse` writes.
struct InverseOutputs {
    csv: Option<PathBuf>,
    plot: Option<PathBuf>,
    states: Option<PathBuf>,
}

fn inverse(
    scene: &Path,
    circle: &flexdyn::robot::Circle,
    duration: f64,
    dt: f64,
    files: &InverseOutputs,
    quiet: bool,
) -> Result<(), String> {
    use flexdyn::robot::{inverse_rows, output_times};
    let (parsed, geometry) = robot_scene(scene, "inverse")?;
    if !(circle.omega.is_finite() && circle.radius.is_finite() && circle.radius >= 0.0) {
        return Err("--omega must be finite and --radius finite and non-negative".into());
    }
    let times = output_times(duration, dt)?;
    let mut progress =
        flexdyn::progress::Progress::new(times.len() as u64, "inverse dynamics", quiet);
    let solutions = flexdyn::with_robot_model!(parsed.name.as_str(), model => {
        inverse_rows(&model, &geometry, circle, &times, &mut || progress.inc())
    })
    .ok_or_else(|| format!("scene `{}` is not a robot scene", parsed.name))??;
    progress.finish();
    let flexible = parsed.nq() > 12;
    let mut columns = vec![
        "t", "tau_1", "tau_2", "tau_3", "px", "py", "pz", "vx", "vy", "vz", "th11", "th21", "th31",
    ];
    if flexible {
        columns.extend(["dx", "dy", "dz"]);
    }
    let mut table = flexdyn::table::Table::new(&columns);
    for s in &solutions {
        // Flexible scenes: the prescribed path, and the platform's deviation from it.
        let [p, v, _] = if flexible {
            circle.at(s.t)
        } else {
            [s.p, s.v, [0.0; 3]]
        };
        let mut row = vec![
            s.t, s.tau[0], s.tau[1], s.tau[2], p[0], p[1], p[2], v[0], v[1], v[2], s.th[0],
            s.th[1], s.th[2],
        ];
        if flexible {
            row.extend((0..3).map(|k| s.p[k] - p[k]));
        }
        table.push(row);
    }
    let mut outputs = flexdyn::table::Outputs::default();
    if let Some(path) = &files.csv {
        outputs.write(path, |tmp| table.write(tmp))?;
    }
    if let Some(path) = &files.states {
        let states: Vec<serde_json::Value> = solutions
            .iter()
            .map(|s| serde_json::json!({ "t": s.t, "q": s.q, "qd": s.qd }))
            .collect();
        let text = serde_json::to_string(&serde_json::json!({ "states": states }))
            .map_err(|e| e.to_string())?;
        outputs.write(path, |tmp| {
            std::fs::write(tmp, text + "\n").map_err(|e| format!("cannot write: {e}"))
        })?;
    }
    if let Some(path) = &files.plot {
        let series: Vec<flexdyn::plot::Series> = (1..=3)
            .map(|i| flexdyn::plot::Series {
                label: ["tau_1", "tau_2", "tau_3"][i - 1],
                points: solutions.iter().map(|s| (s.t, s.tau[i - 1])).collect(),
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
        for i in 0..3 {
            let peak = solutions.iter().map(|s| s.tau[i].abs()).fold(0.0, f64::max);
            println!("chain {}: max |tau_{}| = {:.4} N m", i + 1, i + 1, peak);
        }
    }
    Ok(())
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
    output_dt: f64,
    duration: Option<f64>,
    integrator: Option<flexdyn::robot::Scheme>,
    quiet: bool,
}

fn simulate(a: &SimulateArgs) -> Result<(), String> {
    use flexdyn::robot::{output_times, simulate_rows, PdSettings, Scheme, TorqueTable};
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
    if !(a.output_dt.is_finite() && a.output_dt > 0.0) {
        return Err(format!(
            "--output-dt must be a positive number of seconds, got {}",
            a.output_dt
        ));
    }
    let steps = output_times(duration, a.dt)?.len() - 1;
    let ratio = a.output_dt / a.dt;
    if (ratio - ratio.round()).abs() > 1e-9 * ratio || ratio.round() < 1.0 {
        return Err(format!(
            "--output-dt ({}) must be a whole multiple of --dt ({})",
            a.output_dt, a.dt
        ));
    }
    let every = ratio.round() as usize;
    let mut progress = flexdyn::progress::Progress::new(steps as u64, "forward dynamics", a.quiet);
    let rows = flexdyn::with_robot_model!(parsed.name.as_str(), model => simulate_rows(
        &model,
        &geometry,
        scheme,
        (t0, p, v),
        &torques,
        pd.as_ref(),
        (a.dt, steps, every),
        &mut || progress.inc(),
    ))
    .ok_or_else(|| format!("scene `{}` is not a robot scene", parsed.name))??;
    progress.finish();
    let deviation = |r: &flexdyn::robot::SimRow| {
        let want = path.at(r.t);
        [r.p[0] - want[0], r.p[1] - want[1], r.p[2] - want[2]]
    };
    let mut out = flexdyn::table::Table::new(&[
        "t", "px", "py", "pz", "th11", "th21", "th31", "phi_max", "tau_1", "tau_2", "tau_3", "dx",
        "dy", "dz",
    ]);
    for r in &rows {
        let d = deviation(r);
        out.push(vec![
            r.t, r.p[0], r.p[1], r.p[2], r.th[0], r.th[1], r.th[2], r.phi_max, r.tau[0], r.tau[1],
            r.tau[2], d[0], d[1], d[2],
        ]);
    }
    let mut outputs = flexdyn::table::Outputs::default();
    if let Some(path) = &a.csv {
        outputs.write(path, |tmp| out.write(tmp))?;
    }
    if let Some(plot) = &a.plot {
        let (labels, scale, title, y) = if flexible {
            (
                ["dx", "dy", "dz"],
                1e3,
                format!(
                    "Platform deviation from the torques' path, {}{}",
                    parsed.name,
                    if pd.is_some() { " (with PD)" } else { "" }
                ),
                "deviation (mm)",
            )
        } else {
            (
                ["px", "py", "pz"],
                1.0,
                "Platform position under the given torques".to_string(),
                "position (m)",
            )
        };
        let series: Vec<flexdyn::plot::Series> = labels
            .iter()
            .enumerate()
            .map(|(k, label)| flexdyn::plot::Series {
                label,
                points: rows
                    .iter()
                    .map(|r| (r.t, scale * if flexible { deviation(r)[k] } else { r.p[k] }))
                    .collect(),
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
        let last = rows.last().map_or(0.0, |r| r.t);
        println!(
            "simulated {:.3} s in {} steps of {} s",
            last - t0,
            steps,
            a.dt
        );
        let peak = |k: usize| {
            rows.iter()
                .map(|r| deviation(r)[k].abs())
                .fold(0.0, f64::max)
        };
        println!(
            "max |dx| = {:.4} mm, max |dy| = {:.4} mm, max |dz| = {:.4} mm",
            1e3 * peak(0),
            1e3 * peak(1),
            1e3 * peak(2)
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
    use flexdyn::report::{op_counts, run, run_count, Files, Settings, Study};
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
    flexdyn::report::write(&results, &ops, &files)?;
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
) -> Result<(flexdyn::codegen::model::Model, flexdyn::robot::Geometry), String> {
    let parsed = flexdyn::codegen::model::Model::load(scene).map_err(|e| e.to_string())?;
    if !flexdyn::robot::ROBOT_SCENES.contains(&parsed.name.as_str()) {
        return Err(format!(
            "`{command}` drives the parallel robot; scene `{}` is not one (try scenes/parallel_robot_rigid.toml; \
             robot scenes: {})",
            parsed.name,
            flexdyn::robot::ROBOT_SCENES.join(", ")
        ));
    }
    let geometry = flexdyn::robot::Geometry::from_parameters(&parsed.parameters)?;
    Ok((parsed, geometry))
}
