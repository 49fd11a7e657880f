//! `parallel-robot report`: speed against error of the robot's model variants and
//! integrators, measured on the machine it runs on, written to
//! `docs/performance.md` with its CSV and plots.
//!
//! Two studies on the paper's circle (omega = 2 rad/s):
//!
//! * forward dynamics under the rigid model's inverse-dynamics torques plus
//!   the joint-space PD loop (the paper's Figures 11-16 set-up), for every
//!   model variant, integrator and step: wall time per simulated second
//!   against the largest distance of the platform centre from a reference run
//!   (the full model, generalized-alpha at the finest step);
//! * inverse dynamics (servo constraints for flexible variants, the real-time
//!   path for the rigid one) per variant and step: wall time per simulated
//!   second against the largest torque difference from the reference (the
//!   full model at the finest step).
//!
//! Wall times are medians of repeated runs. The Pareto front of each study
//! and the cheapest configuration under 0.1 mm and 0.01 mm path error (and
//! under 1 % and 0.1 % of the peak torque) are reported.

use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::robot::{
    inverse_rows, output_times, simulate_rows, Circle, Geometry, PdSettings, Scheme, TorqueTable,
};

/// One model variant of the study.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Variant {
    /// Scene name (one of [`crate::robot::ROBOT_SCENES`]).
    pub scene: &'static str,
    /// Modes per flexible link.
    pub modes: usize,
    /// Whether the joints are flexible.
    pub flexible_joints: bool,
    /// Short description.
    pub what: &'static str,
}

/// The variants studied, from the cheapest model to the full one.
pub const VARIANTS: [Variant; 11] = [
    Variant {
        scene: "parallel_robot_rigid",
        modes: 0,
        flexible_joints: false,
        what: "rigid (no joint members)",
    },
    Variant {
        scene: "parallel_robot_flexible_joints",
        modes: 0,
        flexible_joints: true,
        what: "rigid links, flexible joints",
    },
    Variant {
        scene: "parallel_robot_flexible_m1_rigid_joints",
        modes: 1,
        flexible_joints: false,
        what: "1 mode/link, rigid joints",
    },
    Variant {
        scene: "parallel_robot_flexible_m1",
        modes: 1,
        flexible_joints: true,
        what: "1 mode/link, flexible joints",
    },
    Variant {
        scene: "parallel_robot_flexible_m2_rigid_joints",
        modes: 2,
        flexible_joints: false,
        what: "2 modes/link, rigid joints",
    },
    Variant {
        scene: "parallel_robot_flexible_m2",
        modes: 2,
        flexible_joints: true,
        what: "2 modes/link, flexible joints",
    },
    Variant {
        scene: "parallel_robot_flexible_m3",
        modes: 3,
        flexible_joints: true,
        what: "3 modes/link, flexible joints",
    },
    Variant {
        scene: "parallel_robot_flexible_m4",
        modes: 4,
        flexible_joints: true,
        what: "4 modes/link, flexible joints",
    },
    Variant {
        scene: "parallel_robot_flexible_m6_rigid_joints",
        modes: 6,
        flexible_joints: false,
        what: "6 modes/link, rigid joints",
    },
    Variant {
        scene: "parallel_robot_flexible_pruned",
        modes: 6,
        flexible_joints: true,
        what: "full, terms below 1e-6 dropped",
    },
    Variant {
        scene: "parallel_robot_flexible",
        modes: 6,
        flexible_joints: true,
        what: "full model (6 modes/link, flexible joints)",
    },
];

/// The full model, which the references are run with.
pub const FULL: &str = "parallel_robot_flexible";

/// What to measure.
#[derive(Debug, Clone)]
pub struct Settings {
    /// Simulated time per run, s.
    pub duration: f64,
    /// Timed repetitions of each run (the median is reported).
    pub repeats: usize,
    /// Steps of the forward runs, s.
    pub forward_steps: Vec<f64>,
    /// Steps of the inverse-dynamics runs, s.
    pub inverse_steps: Vec<f64>,
    /// Step of the forward reference run, s.
    pub forward_reference: f64,
    /// Step of the inverse-dynamics reference run, s.
    pub inverse_reference: f64,
    /// Integrators of the forward study.
    pub schemes: Vec<Scheme>,
    /// Variants studied.
    pub variants: Vec<Variant>,
    /// Grid the runs are compared on, s (a multiple of every step).
    pub grid: f64,
    /// Angular rate of the circle, rad/s.
    pub omega: f64,
}

impl Settings {
    /// The full study (a few minutes on a laptop-class core).
    pub fn full() -> Settings {
        Settings {
            duration: 1.0,
            repeats: 3,
            forward_steps: vec![0.0005, 0.001, 0.002, 0.005, 0.01, 0.02],
            inverse_steps: vec![0.001, 0.005, 0.01],
            forward_reference: 0.0001,
            inverse_reference: 0.0005,
            schemes: vec![Scheme::GeneralizedAlpha, Scheme::SemiImplicit, Scheme::Rk4],
            variants: VARIANTS.to_vec(),
            grid: 0.02,
            omega: 2.0,
        }
    }

    /// A small study for tests (seconds).
    pub fn quick() -> Settings {
        let pick = |s: &str| VARIANTS.iter().copied().find(|v| v.scene == s);
        Settings {
            duration: 0.2,
            repeats: 1,
            forward_steps: vec![0.0025, 0.005, 0.01],
            inverse_steps: vec![0.005, 0.01],
            forward_reference: 0.0005,
            inverse_reference: 0.0025,
            schemes: vec![Scheme::GeneralizedAlpha, Scheme::Rk4],
            variants: ["parallel_robot_rigid", "parallel_robot_flexible_m1", FULL]
                .into_iter()
                .filter_map(pick)
                .collect(),
            grid: 0.01,
            omega: 2.0,
        }
    }
}

/// Name of a scheme as the command line spells it.
pub fn scheme_name(s: Scheme) -> &'static str {
    match s {
        Scheme::Rk4 => "rk4",
        Scheme::SemiImplicit => "semi-implicit",
        Scheme::GeneralizedAlpha => "gen-alpha",
    }
}

/// One measured configuration.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    /// The model variant.
    pub variant: Variant,
    /// Integrator (`None` for the rigid model's algebraic inverse dynamics).
    pub scheme: Option<Scheme>,
    /// Step, s.
    pub dt: f64,
    /// Median wall time per simulated second, s; or why the run failed.
    pub outcome: Result<Outcome, String>,
}

/// Cost and error of a configuration that ran.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Outcome {
    /// Median wall time per simulated second, s.
    pub cost: f64,
    /// Error against the reference (m for paths, N m for torques).
    pub error: f64,
}

/// The configurations of `points` (cost, error) that no other beats in both
/// (indices, cheapest first): the Pareto front.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..points.len()).collect();
    order.sort_by(|&a, &b| {
        points[a]
            .0
            .total_cmp(&points[b].0)
            .then(points[a].1.total_cmp(&points[b].1))
    });
    let mut front = Vec::new();
    let mut best = f64::INFINITY;
    for i in order {
        if points[i].1 < best {
            best = points[i].1;
            front.push(i);
        }
    }
    front
}

/// The cheapest of `points` (cost, error) with an error below `limit`.
pub fn cheapest_under(points: &[(f64, f64)], limit: f64) -> Option<usize> {
    (0..points.len())
        .filter(|&i| points[i].1 < limit)
        .min_by(|&a, &b| points[a].0.total_cmp(&points[b].0))
}

/// Largest distance between two sampled paths (Euclidean) or torque
/// histories (largest single difference); NaN if any value is.
fn distance(a: &[[f64; 3]], b: &[[f64; 3]], euclidean: bool) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| {
            let d: [f64; 3] = std::array::from_fn(|k| x[k] - y[k]);
            if euclidean {
                d.iter().map(|v| v * v).sum::<f64>().sqrt()
            } else {
                d.iter().fold(0.0f64, |m, v| m.max(v.abs()))
            }
        })
        .fold(0.0f64, |m, x| {
            if x.is_nan() || m.is_nan() {
                f64::NAN
            } else {
                m.max(x)
            }
        })
}

/// Median of a non-empty list.
fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Steps of `dt` between grid points.
fn every(grid: f64, dt: f64) -> Result<usize, String> {
    flexdyn::steps::per_output("the grid", grid, "the step", dt).map(|n| n as usize)
}

/// The study's fixed inputs.
pub struct Study {
    settings: Settings,
    geometry: Geometry,
    circle: Circle,
    torques: TorqueTable,
    pd: PdSettings,
}

impl Study {
    /// Prepare: the rigid robot's torques along the circle (the feed-forward
    /// of every forward run) and the PD gains of the full scene.
    pub fn new(settings: Settings, scenes: &Path) -> Result<Study, String> {
        let full = flexdyn::codegen::Model::load(&scenes.join(format!("{FULL}.toml")))
            .map_err(|e| e.to_string())?;
        let geometry = Geometry::from_parameters(&full.parameters)?;
        let gain = |name: &str| {
            full.parameters
                .get(name)
                .copied()
                .ok_or_else(|| format!("scene `{FULL}` declares no `{name}`"))
        };
        let circle = Circle::paper(settings.omega);
        // Torques tabulated at the finest forward step and a little beyond
        // the end, so that interpolation never changes with the run's step.
        let times = output_times(
            settings.duration + settings.grid,
            settings.forward_reference,
            flexdyn::steps::MAX_STEPS,
        )?;
        let rows = crate::with_robot_model!("parallel_robot_rigid", m => {
            inverse_rows(&m, &geometry, &circle, &times, &mut || {})
        })
        .ok_or("the rigid robot is not compiled in")??;
        let samples: Vec<(f64, [f64; 3])> = rows.iter().map(|r| (r.t, r.tau)).collect();
        let angles: Vec<(f64, [f64; 3])> = rows.iter().map(|r| (r.t, r.th)).collect();
        let pd = PdSettings {
            kp: gain("pd_kp")?,
            kd: gain("pd_kd")?,
            reference: TorqueTable::from_samples(&angles)?,
        };
        Ok(Study {
            torques: TorqueTable::from_samples(&samples)?,
            settings,
            geometry,
            circle,
            pd,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// A forward run of `scene`: the platform centre on the grid and the wall
    /// time, s.
    pub fn forward(
        &self,
        scene: &str,
        scheme: Scheme,
        dt: f64,
    ) -> Result<(Vec<[f64; 3]>, f64), String> {
        let s = &self.settings;
        let steps = output_times(s.duration, dt, flexdyn::steps::MAX_STEPS)?.len() - 1;
        let every = every(s.grid, dt)?;
        let [p, v, _] = self.circle.at(0.0);
        let start = Instant::now();
        let rows = crate::with_robot_model!(scene, m => simulate_rows(
            &m,
            &self.geometry,
            scheme,
            (0.0, p, v),
            &self.torques,
            Some(&self.pd),
            (dt, steps, every),
            &mut || {},
        ))
        .ok_or_else(|| format!("scene `{scene}` is not a robot scene"))??;
        let wall = start.elapsed().as_secs_f64();
        Ok((rows.iter().map(|r| r.p).collect(), wall))
    }

    /// An inverse-dynamics run of `scene`: the torques on the grid and the
    /// wall time, s.
    pub fn inverse(&self, scene: &str, dt: f64) -> Result<(Vec<[f64; 3]>, f64), String> {
        let s = &self.settings;
        let times = output_times(s.duration, dt, flexdyn::steps::MAX_STEPS)?;
        let every = every(s.grid, dt)?;
        let start = Instant::now();
        let rows = crate::with_robot_model!(scene, m => {
            inverse_rows(&m, &self.geometry, &self.circle, &times, &mut || {})
        })
        .ok_or_else(|| format!("scene `{scene}` is not a robot scene"))??;
        let wall = start.elapsed().as_secs_f64();
        Ok((rows.iter().step_by(every).map(|r| r.tau).collect(), wall))
    }

    /// Repeat `run` and measure its median wall time per simulated second
    /// and its error against `reference` (largest Euclidean distance on the
    /// grid for paths, largest single torque difference for torques).
    fn measure(
        &self,
        run: &dyn Fn() -> Result<(Vec<[f64; 3]>, f64), String>,
        reference: &[[f64; 3]],
        euclidean: bool,
    ) -> Result<Outcome, String> {
        let mut walls = Vec::new();
        let mut values = Vec::new();
        for _ in 0..self.settings.repeats.max(1) {
            let (v, wall) = run()?;
            walls.push(wall);
            values = v;
        }
        if values.len() != reference.len() {
            return Err(format!(
                "{} grid points against {} of the reference",
                values.len(),
                reference.len()
            ));
        }
        let error = distance(&values, reference, euclidean);
        if !error.is_finite() {
            return Err("the run produced non-finite values".into());
        }
        Ok(Outcome {
            cost: median(walls) / self.settings.duration,
            error,
        })
    }
}

/// Everything the report shows.
pub struct Results {
    /// The settings measured with.
    pub settings: Settings,
    /// Forward runs.
    pub forward: Vec<Measurement>,
    /// Inverse-dynamics runs.
    pub inverse: Vec<Measurement>,
    /// Distance between the forward reference and the same run at twice its
    /// step (an estimate of the reference's own error), m.
    pub forward_reference_error: f64,
    /// The same for the inverse-dynamics reference, N m.
    pub inverse_reference_error: f64,
    /// Largest reference torque, N m.
    pub peak_torque: f64,
    /// Wall time of the whole study, s.
    pub elapsed: f64,
}

/// Run the study, calling `tick` after each run.
pub fn run(study: &Study, tick: &mut dyn FnMut(&str)) -> Result<Results, String> {
    let start = Instant::now();
    let s = study.settings();
    let fail = |what: &str, e: String| format!("reference run ({what}): {e}");
    let (fwd_ref, _) = study
        .forward(FULL, Scheme::GeneralizedAlpha, s.forward_reference)
        .map_err(|e| fail("forward", e))?;
    let (fwd_half, _) = study
        .forward(FULL, Scheme::GeneralizedAlpha, 2.0 * s.forward_reference)
        .map_err(|e| fail("forward", e))?;
    tick("forward reference");
    let (inv_ref, _) = study
        .inverse(FULL, s.inverse_reference)
        .map_err(|e| fail("inverse", e))?;
    let (inv_half, _) = study
        .inverse(FULL, 2.0 * s.inverse_reference)
        .map_err(|e| fail("inverse", e))?;
    tick("inverse reference");
    let forward_reference_error = distance(&fwd_ref, &fwd_half, true);
    let inverse_reference_error = distance(&inv_ref, &inv_half, false);
    let peak_torque = inv_ref
        .iter()
        .flat_map(|t| t.iter())
        .fold(0.0f64, |m, x| m.max(x.abs()));

    let mut forward = Vec::new();
    for &variant in &s.variants {
        for &scheme in &s.schemes {
            for &dt in &s.forward_steps {
                let outcome =
                    study.measure(&|| study.forward(variant.scene, scheme, dt), &fwd_ref, true);
                forward.push(Measurement {
                    variant,
                    scheme: Some(scheme),
                    dt,
                    outcome,
                });
                tick(variant.scene);
            }
        }
    }
    let mut inverse = Vec::new();
    for &variant in &s.variants {
        for &dt in &s.inverse_steps {
            let outcome = study.measure(&|| study.inverse(variant.scene, dt), &inv_ref, false);
            let scheme =
                (variant.scene != "parallel_robot_rigid").then_some(Scheme::GeneralizedAlpha);
            inverse.push(Measurement {
                variant,
                scheme,
                dt,
                outcome,
            });
            tick(variant.scene);
        }
    }
    Ok(Results {
        settings: s.clone(),
        forward,
        inverse,
        forward_reference_error,
        inverse_reference_error,
        peak_torque,
        elapsed: start.elapsed().as_secs_f64(),
    })
}

/// Number of runs [`run`] makes (for a progress bar).
pub fn run_count(s: &Settings) -> usize {
    2 + s.variants.len() * (s.schemes.len() * s.forward_steps.len() + s.inverse_steps.len())
}

/// The machine and the date, for the report's header.
pub fn machine() -> String {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split(':').nth(1))
                .map(|s| s.trim().to_owned())
        })
        .unwrap_or_else(|| "unknown CPU".into());
    let cores = std::thread::available_parallelism().map_or(0, |n| n.get());
    format!(
        "{cpu}, {cores} core(s) available, {} {}",
        std::env::consts::OS,
        std::env::consts::ARCH
    )
}

/// Today's date (UTC) as `YYYY-MM-DD`.
pub fn today() -> String {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (y, m, d) = civil_from_days((secs / 86_400) as i64);
    format!("{y:04}-{m:02}-{d:02}")
}

/// Gregorian date of a day count since 1970-01-01 (the proleptic
/// calendar's era arithmetic).
pub fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    (yoe + era * 400 + i64::from(m <= 2), m, d)
}

/// Operation count of `dynamics_terms` and the coordinates of each scene, from
/// the generator.
pub fn op_counts(scenes: &Path, variants: &[Variant]) -> Result<Vec<(usize, usize)>, String> {
    variants
        .iter()
        .map(|v| {
            let g = flexdyn::codegen::generate_scene(&scenes.join(format!("{}.toml", v.scene)))
                .map_err(|e| e.to_string())?;
            let ops = g
                .functions
                .iter()
                .find(|f| f.name == "dynamics_terms")
                .map_or(0, |f| f.ops.total());
            Ok((g.dims.0, ops))
        })
        .collect()
}

/// Where the report's files go: the Markdown page and, in a folder named
/// after it, the CSV and plots.
#[derive(Debug, Clone)]
pub struct Files {
    /// The Markdown page.
    pub page: PathBuf,
    /// Folder of CSV and plots.
    pub dir: PathBuf,
}

impl Files {
    /// `page` and the folder `page` without its extension.
    pub fn new(page: &Path) -> Files {
        Files {
            page: page.to_path_buf(),
            dir: page.with_extension(""),
        }
    }
}

fn fmt_outcome(m: &Measurement, unit: f64, digits: usize) -> (String, String) {
    match &m.outcome {
        Ok(o) => (
            format!("{:.3}", 1e3 * o.cost),
            format!("{:.*e}", digits, o.error * unit),
        ),
        Err(e) => {
            let mut short: String = e.chars().take(140).collect();
            if short.len() < e.len() {
                short.push_str("...");
            }
            ("-".into(), format!("failed: {}", short.replace('|', "/")))
        }
    }
}

fn config_name(m: &Measurement) -> String {
    let scheme = m.scheme.map_or("algebraic", scheme_name);
    format!("{} / {scheme} / {} ms", m.variant.scene, 1e3 * m.dt)
}

/// Points of the configurations that ran, with their indices.
fn points(ms: &[Measurement]) -> (Vec<usize>, Vec<(f64, f64)>) {
    ms.iter()
        .enumerate()
        .filter_map(|(i, m)| m.outcome.as_ref().ok().map(|o| (i, (o.cost, o.error))))
        .unzip()
}

/// Write the page, its CSV files and its plots (all or nothing).
pub fn write(results: &Results, ops: &[(usize, usize)], files: &Files) -> Result<(), String> {
    std::fs::create_dir_all(&files.dir)
        .map_err(|e| format!("cannot create {}: {e}", files.dir.display()))?;
    let mut out = flexdyn::table::OutputFiles::default();
    let dir_name = files
        .dir
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let s = &results.settings;
    let ops_of = |v: &Variant| {
        s.variants
            .iter()
            .position(|x| x == v)
            .map_or((0, 0), |k| ops[k])
    };

    // CSV of every run.
    let mut csv = String::from("study,scene,modes,flexible_joints,coordinates,ops,integrator,dt,wall_per_simulated_s,error,failure\n");
    for (study, ms) in [("forward", &results.forward), ("inverse", &results.inverse)] {
        for m in ms.iter() {
            let (nq, nops) = ops_of(&m.variant);
            let (cost, error, why) = match &m.outcome {
                Ok(o) => (
                    format!("{:?}", o.cost),
                    format!("{:?}", o.error),
                    String::new(),
                ),
                Err(e) => (String::new(), String::new(), e.replace([',', '\n'], ";")),
            };
            csv.push_str(&format!(
                "{study},{},{},{},{nq},{nops},{},{:?},{cost},{error},{why}\n",
                m.variant.scene,
                m.variant.modes,
                m.variant.flexible_joints,
                m.scheme.map_or("algebraic", scheme_name),
                m.dt,
            ));
        }
    }
    out.write(&files.dir.join("runs.csv"), |p| {
        std::fs::write(p, &csv).map_err(|e| format!("cannot write {}: {e}", p.display()))
    })?;

    // Plots.
    let plot = |ms: &[Measurement], unit: f64, title: &str, y: &str| {
        let groups: Vec<(String, Vec<(f64, f64)>)> = s
            .variants
            .iter()
            .map(|v| {
                let pts = ms
                    .iter()
                    .filter(|m| m.variant == *v)
                    .filter_map(|m| m.outcome.as_ref().ok())
                    .map(|o| (1e3 * o.cost, unit * o.error))
                    .collect();
                (
                    v.scene.trim_start_matches("parallel_robot_").to_owned(),
                    pts,
                )
            })
            .collect();
        let (_, pts) = points(ms);
        let front: Vec<(f64, f64)> = pareto_front(&pts)
            .into_iter()
            .map(|i| (1e3 * pts[i].0, unit * pts[i].1))
            .collect();
        (groups, front, title.to_owned(), y.to_owned())
    };
    for (name, (groups, front, title, y)) in [
        (
            "pareto_path.png",
            plot(
                &results.forward,
                1e3,
                "Forward dynamics: cost against path error",
                "path error (mm)",
            ),
        ),
        (
            "pareto_torque.png",
            plot(
                &results.inverse,
                1.0,
                "Inverse dynamics: cost against torque error",
                "torque error (N m)",
            ),
        ),
    ] {
        out.write(&files.dir.join(name), |p| {
            flexdyn::plot::scatter_plot(
                p,
                &flexdyn::plot::Labels {
                    title: &title,
                    x: "wall time per simulated second (ms)",
                    y: &y,
                },
                &groups,
                &front,
            )
        })?;
    }

    // The page.
    let mut md = String::new();
    let push = |md: &mut String, line: &str| {
        md.push_str(line);
        md.push('\n');
    };
    push(&mut md, "# Performance: speed against error");
    push(&mut md, "");
    push(
        &mut md,
        &format!(
            "Written by `parallel-robot report` on {} ({}), {}. Every wall time is the median of {} \
         repeated runs on this machine (the whole study took {:.0} s); errors do not depend \
         on the machine. Regenerate with `cargo run --release -p flexdyn-parallel-robot -- report` (add `--quick` for \
         a small version). The CSV of every run and the plots are in [{dir_name}/]({dir_name}/).",
            today(),
            machine(),
            "release build",
            s.repeats.max(1),
            results.elapsed
        ),
    );
    push(&mut md, "");
    push(&mut md, "## Set-up");
    push(&mut md, "");
    push(
        &mut md,
        &format!(
        "The paper's circle (radius 0.1 m, centre (0, 0, 0.7) m) at omega = {} rad/s for {} s. \
         Forward runs: every model variant under the rigid model's inverse-dynamics torques \
         plus the joint-space PD loop of the full scene (`pd_kp`, `pd_kd`), starting from the \
         static equilibrium on the path (the `parallel-robot simulate --pd` set-up). Path error: the \
         largest distance of the platform centre from the reference run on a {} ms grid; the \
         reference is the full model with generalized-alpha at {} ms, which differs from the \
         same run at twice its step by {:.2e} mm. Inverse dynamics: servo constraints on the \
         platform with the elastic coordinates integrated (generalized-alpha) for the flexible \
         variants, the real-time algebraic path for the rigid one; torque error: the largest \
         difference of any actuator torque from the full model at {} ms (which differs from \
         its run at twice the step by {:.2e} N m; peak torque {:.2} N m).",
        s.omega,
        s.duration,
        1e3 * s.grid,
        1e3 * s.forward_reference,
        1e3 * results.forward_reference_error,
        1e3 * s.inverse_reference,
        results.inverse_reference_error,
        results.peak_torque
    ),
    );
    push(&mut md, "");
    push(
        &mut md,
        "| variant | scene | coordinates | ops of `dynamics_terms` |",
    );
    push(&mut md, "|---|---|---|---|");
    for (k, v) in s.variants.iter().enumerate() {
        push(
            &mut md,
            &format!(
                "| {} | `{}` | {} | {} |",
                v.what, v.scene, ops[k].0, ops[k].1
            ),
        );
    }
    push(&mut md, "");

    let recommend = |md: &mut String, ms: &[Measurement], limits: &[(f64, &str)]| {
        let (idx, pts) = points(ms);
        for &(limit, text) in limits {
            let line = match cheapest_under(&pts, limit) {
                Some(i) => {
                    let m = &ms[idx[i]];
                    format!(
                        "- Cheapest under {text}: **{}** ({}), {:.3} ms per simulated second.",
                        config_name(m),
                        m.variant.what,
                        1e3 * pts[i].0
                    )
                }
                None => format!("- Nothing measured stays under {text}."),
            };
            push(md, &line);
        }
        let front: Vec<String> = pareto_front(&pts)
            .into_iter()
            .map(|i| format!("`{}`", config_name(&ms[idx[i]])))
            .collect();
        push(
            md,
            &format!("- Pareto front, cheapest first: {}.", front.join(", ")),
        );
    };

    push(&mut md, "## Forward dynamics: path error against cost");
    push(&mut md, "");
    push(
        &mut md,
        &format!("![forward Pareto plot]({dir_name}/pareto_path.png)"),
    );
    push(&mut md, "");
    recommend(
        &mut md,
        &results.forward,
        &[(1e-4, "0.1 mm"), (1e-5, "0.01 mm")],
    );
    push(&mut md, "");
    push(
        &mut md,
        "| scene | integrator | step (ms) | ms per simulated s | path error (mm) |",
    );
    push(&mut md, "|---|---|---|---|---|");
    for m in &results.forward {
        let (cost, err) = fmt_outcome(m, 1e3, 2);
        push(
            &mut md,
            &format!(
                "| `{}` | {} | {} | {cost} | {err} |",
                m.variant.scene,
                m.scheme.map_or("algebraic", scheme_name),
                1e3 * m.dt
            ),
        );
    }
    push(&mut md, "");
    push(&mut md, "## Inverse dynamics: torque error against cost");
    push(&mut md, "");
    push(
        &mut md,
        &format!("![inverse Pareto plot]({dir_name}/pareto_torque.png)"),
    );
    push(&mut md, "");
    let peak = results.peak_torque.max(1e-300);
    recommend(
        &mut md,
        &results.inverse,
        &[
            (0.01 * peak, "1 % of the peak torque"),
            (0.001 * peak, "0.1 % of the peak torque"),
        ],
    );
    push(&mut md, "");
    push(
        &mut md,
        "| scene | method | step (ms) | ms per simulated s | torque error (N m) |",
    );
    push(&mut md, "|---|---|---|---|---|");
    for m in &results.inverse {
        let (cost, err) = fmt_outcome(m, 1.0, 2);
        push(
            &mut md,
            &format!(
                "| `{}` | {} | {} | {cost} | {err} |",
                m.variant.scene,
                m.scheme.map_or("algebraic (real-time path)", |_| {
                    "servo constraints, gen-alpha"
                }),
                1e3 * m.dt
            ),
        );
    }
    push(&mut md, "");
    push(&mut md, "## Model only what a scene needs");
    push(&mut md, "");
    push(
        &mut md,
        "Each reduction of the full model (a derived scene with a `[reduce]` table: \
        `modes`, `freeze`, `drop_below`; see docs/scene-format.md), with what it saves and \
        what it costs, at the paper's step of 5 ms with generalized-alpha:",
    );
    push(&mut md, "");
    push(&mut md, "| variant | coordinates | ops | ms per simulated s (forward) | path error (mm) | ms per simulated s (inverse) | torque error (N m) |");
    push(&mut md, "|---|---|---|---|---|---|---|");
    let at = |ms: &[Measurement], v: &Variant, scheme: Option<Scheme>| {
        ms.iter()
            .filter(|m| m.variant == *v && (m.scheme == scheme || scheme.is_none()))
            .min_by(|a, b| (a.dt - 0.005).abs().total_cmp(&(b.dt - 0.005).abs()))
            .cloned()
    };
    for (k, v) in s.variants.iter().enumerate() {
        let f = at(&results.forward, v, Some(Scheme::GeneralizedAlpha));
        let i = at(&results.inverse, v, None);
        let cell = |m: Option<Measurement>, unit: f64| {
            m.map_or(("-".into(), "-".into()), |m| fmt_outcome(&m, unit, 2))
        };
        let (fc, fe) = cell(f, 1e3);
        let (ic, ie) = cell(i, 1.0);
        push(
            &mut md,
            &format!(
                "| {} | {} | {} | {fc} | {fe} | {ic} | {ie} |",
                v.what, ops[k].0, ops[k].1
            ),
        );
    }
    push(&mut md, "");
    // Where the explicit schemes ran on elastic models, from the runs.
    let explicit: Vec<String> = results
        .forward
        .iter()
        .filter(|m| {
            m.scheme.is_some_and(|x| x != Scheme::GeneralizedAlpha)
                && m.variant.scene != "parallel_robot_rigid"
                && m.outcome.is_ok()
        })
        .map(|m| format!("`{}`", config_name(m)))
        .collect();
    let implicit_failures: Vec<String> = results
        .forward
        .iter()
        .filter(|m| m.scheme == Some(Scheme::GeneralizedAlpha) && m.outcome.is_err())
        .map(|m| format!("`{}`", config_name(m)))
        .collect();
    let list = |v: &[String]| {
        if v.is_empty() {
            "none".to_owned()
        } else {
            v.join(", ")
        }
    };
    push(
        &mut md,
        &format!(
        "Explicit schemes (RK4, semi-implicit Euler) were refused (RK4: the runtime's stability \
         bound) or diverged on every elastic variant at every step measured, except: {}. \
         Generalized-alpha failed on: {}. Torque errors below the inverse-dynamics \
         reference's own step dependence ({:.2e} N m) do not tell the variants apart.",
        list(&explicit),
        list(&implicit_failures),
        results.inverse_reference_error
    ),
    );
    push(&mut md, "");
    push(&mut md, "## Single precision (f32)");
    push(&mut md, "");
    push(
        &mut md,
        "The same scenes generated with `precision = \"f32\"` run the runtime's model terms, \
         inverse dynamics, RK4, Gauss-Legendre, generalized-alpha and the servo constraints in \
         f32 (for single-precision FPUs). Measured against f64 (the tests `f32_runtime` and \
         `flexible_robot_servo_f32` of examples/cortex-m-bench): the rigid robot's torques \
         along this circle agree to 2.2e-6 of the peak torque and its coordinates to 4.5e-6; \
         near the workspace edge the f32 error grows as the Jacobian's condition times 1.2e-7. \
         The flexible robot's servo inverse dynamics (2 rad/s, 5 ms, one turn): torques within \
         8.3e-6 of the peak, the platform within 2.7e-6 m of the circle (f64: 1.5e-6 m), but \
         the flexible joints' deflections (1e-8 rad) not resolved at all; at 10 rad/s the \
         torques are off by 3.1e-3 of the peak at 5 ms and 0.21 at 0.5 ms, and at 50 ms f32 \
         refuses (Newton matrix condition). Its stiffness spread (7e11, beyond f32's 1/eps = \
         8.4e6) makes the generator refuse the flexible variants in f32 unless overridden. \
         Cost on a Cortex-M4F, the hard cases and the f32 limits: \
         [docs/embedded.md](../../../docs/embedded.md#f32-or-f64).",
    );
    out.write(&files.page, |p| {
        std::fs::write(p, &md).map_err(|e| format!("cannot write {}: {e}", p.display()))
    })?;
    out.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_front_keeps_the_non_dominated_points() {
        // (cost, error): 1 dominates 3 (cheaper and better); 4 is the best error.
        let pts = [
            (2.0, 5.0),
            (1.0, 4.0),
            (3.0, 1.0),
            (1.5, 4.5),
            (4.0, 0.5),
            (5.0, 0.5),
        ];
        assert_eq!(pareto_front(&pts), vec![1, 2, 4]);
        assert!(pareto_front(&[]).is_empty());
    }

    #[test]
    fn cheapest_under_a_limit() {
        let pts = [(2.0, 5.0), (1.0, 4.0), (3.0, 1.0), (4.0, 0.5)];
        assert_eq!(cheapest_under(&pts, 4.5), Some(1));
        assert_eq!(cheapest_under(&pts, 1.5), Some(2));
        assert_eq!(cheapest_under(&pts, 0.1), None);
    }

    #[test]
    fn civil_dates() {
        // Known dates: the epoch, a leap day, and the day this was written.
        assert_eq!(civil_from_days(0), (1970, 1, 1));
        assert_eq!(civil_from_days(11_016), (2000, 2, 29));
        assert_eq!(civil_from_days(20_414), (2025, 11, 22));
        assert_eq!(civil_from_days(-1), (1969, 12, 31));
    }

    #[test]
    fn medians() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 2.0, 3.0]), 2.5);
    }
}
