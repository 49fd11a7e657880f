//! `flexdyn simulate`: forward dynamics of any scene file under given
//! inputs, written as CSV (and optionally plotted).
//!
//! The scene runs at its own size (`dyn DynModel` is the runtime's
//! `Equations` over run-time dimensions, [`crate::dynamic`]): a
//! compiled-in scene by its compiled module (when the file describes the same
//! model, checked bitwise at a sample state), any other by the interpreter.
//! The initial state (the scene's `initial` / `initial_velocity`, or
//! `--initial`) is projected onto `Phi(q, t) = 0` and `Phi_q qd + Phi_t = 0`
//! (`flexdyn_runtime::project`: mass-weighted minimum-norm corrections).
//! Inputs per actuator: a function of time (`--input`) or a column of a CSV
//! (`--inputs`, linear in between), plus joint PD feedback (`--pd`, through
//! `control::JointPd` and `control::Feedback`) towards a target given as a
//! function of time (`--target`) or a CSV column (its rate the slope of the
//! linear interpolation, or a column `<coordinate>_dot` interpolated
//! linearly); zero otherwise.

use std::path::PathBuf;

use flexdyn_runtime::control::{Feedback, FeedbackLaw, JointPdOf, TargetOf};
use flexdyn_runtime::{
    project, AdaptiveRk4, Equations, ErrorKind, FromFn, GaussLegendre4, GeneralizedAlphaConfig,
    GeneralizedAlphaOf, InputOf, IntegratorOf, ProjectionConfig, Rk4, SemiImplicitEuler, StateOf,
    StepSettings, Time,
};
use nalgebra::{DVector, Dyn};

use crate::codegen::TimeFunction;
use crate::compiled::Compiled;
use crate::dynamic::{matrix, no_mass_hint, vector, DynModel};
use crate::error_estimate::{Companion, ErrorEstimate, LOOSENED};
use crate::plot::{line_plot, Decimated, Labels, Series, PLOT_ROWS};
use crate::progress::Progress;
use crate::steps::{count, per_output, Last, MAX_STEPS};
use crate::table::{check_output, CsvWriter, OutputFiles, Table};

/// The integrators `--integrator` accepts.
pub const INTEGRATORS: [&str; 5] = [
    "adaptive-rk4",
    "rk4",
    "semi-implicit-euler",
    "gauss-legendre",
    "gen-alpha",
];

/// Simulate a scene from its initial state under inputs; write the motion as
/// CSV: `t`, every coordinate, `<name>_dot` of every velocity, `T`, `V`,
/// `drift` (norm of the constraint residuals), then `<marker>_x`,
/// `<marker>_y`, `<marker>_z` (world position) of the scene's markers.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file (any; a compiled-in scene runs compiled).
    #[arg(long)]
    pub scene: PathBuf,
    /// Interpret the scene file even when a scene of its name is compiled in.
    #[arg(long)]
    pub interpret: bool,
    /// Simulated time span, s.
    #[arg(long)]
    pub duration: f64,
    /// Step of the fixed-step integrators, s, and the output step unless
    /// --output-dt is given (default 0.01); adaptive-rk4 chooses its own
    /// steps and takes this as its output step. At most --max-steps steps
    /// of it fit in --duration (the last one shortened to end there).
    #[arg(long)]
    pub dt: Option<f64>,
    /// Output step, s (default: --dt): a whole multiple of --dt for the
    /// fixed-step integrators.
    #[arg(long)]
    pub output_dt: Option<f64>,
    /// Initial state as JSON (`{"q": [..], "qd": [..], "t": 0}`); default:
    /// the scene's `initial` / `initial_velocity` values.
    #[arg(long)]
    pub initial: Option<PathBuf>,
    /// Input of an actuator as a function of time: `NAME=EXPR` (scene
    /// grammar with `t` and the scene's parameters). Repeatable.
    #[arg(long = "input", value_name = "NAME=EXPR")]
    pub inputs_expr: Vec<String>,
    /// Inputs from a CSV: column `t` (increasing), actuator columns by name,
    /// and PD targets as columns named after coordinates, with their rates
    /// as columns `<coordinate>_dot` if given (otherwise the slopes); linear
    /// in between, held constant outside (rates zero there).
    #[arg(long = "inputs", value_name = "U.csv")]
    pub inputs_csv: Option<PathBuf>,
    /// Joint PD feedback on an actuator, `NAME=KP,KD`, towards the target of
    /// the coordinate the actuator drives (`--target` or a CSV column),
    /// added to the actuator's open-loop input if it has one (feed-forward).
    #[arg(long, value_name = "NAME=KP,KD")]
    pub pd: Vec<String>,
    /// Target of a PD-driven coordinate: `COORD=EXPR`.
    #[arg(long, value_name = "COORD=EXPR")]
    pub target: Vec<String>,
    /// Linear state feedback `u = u0 - K (x - x0)` from JSON: the output of
    /// `flexdyn linearize` with a gain matrix `"K"` (one row per input of
    /// its `inputs`, one gain per entry of its `states`: coordinates and
    /// `<coordinate>_dot` rates), added to the other inputs.
    #[arg(long, value_name = "K.json")]
    pub feedback: Option<PathBuf>,
    /// Integrator: adaptive-rk4 (default), rk4, semi-implicit-euler,
    /// gauss-legendre, gen-alpha.
    #[arg(long, default_value = "adaptive-rk4")]
    pub integrator: String,
    /// Relative tolerance of adaptive-rk4 (absolute: 1/100 of it; default
    /// 1e-8). Refused with the fixed-step integrators, which would ignore it.
    #[arg(long)]
    pub tolerance: Option<f64>,
    /// Spectral radius at infinite frequency of gen-alpha, in [0, 1]
    /// (default 0.8; 1: no numerical damping, 0: the most). Refused with the
    /// other integrators.
    #[arg(long)]
    pub rho_inf: Option<f64>,
    /// Start gen-alpha with its auxiliary acceleration equal to the
    /// acceleration (as the parallel-robot example and `flexdyn inverse`
    /// do) instead of the low-pass filtered one, which keeps unresolved
    /// stiff modes from overshooting in the first step. Refused with the
    /// other integrators.
    #[arg(long)]
    pub unfiltered_start: bool,
    /// Most fixed-point sweeps per step of gauss-legendre (default 50).
    /// Refused with the other integrators.
    #[arg(long)]
    pub max_sweeps: Option<u32>,
    /// No error estimate: by default a companion run at twice the step
    /// (adaptive-rk4: 16 times the tolerance) goes along, about half as much
    /// work again, and their difference estimates the error of the run,
    /// printed at the end and a warning above 1e-3 of a quantity's scale.
    #[arg(long)]
    pub no_error_estimate: bool,
    /// Largest number of steps: of --dt in --duration (refused before the
    /// run), and of adaptive-rk4's accepted steps (the run stops with an
    /// error naming the time reached).
    #[arg(long, default_value_t = MAX_STEPS)]
    pub max_steps: u64,
    /// Output CSV, written row by row as the run goes (a regular file
    /// appears whole when the run succeeds, or not at all; a device or FIFO
    /// gets the rows as they come).
    #[arg(long)]
    pub csv: PathBuf,
    /// Plot of the chosen columns (`.png` or `.svg`); of a run longer than
    /// 4096 rows, a plot of evenly spaced rows (every second, fourth, ...:
    /// at most 4096 and the last; the CSV has them all).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Markers whose world position is written (`<name>_x`, `_y`, `_z`
    /// after `drift`), comma-separated: all of the scene's by default,
    /// `none` for none.
    #[arg(long, value_delimiter = ',', value_name = "NAMES")]
    pub markers: Vec<String>,
    /// Columns to plot, comma-separated (default: the coordinates).
    #[arg(long, value_delimiter = ',')]
    pub columns: Vec<String>,
    /// Nothing on stderr unless it fails: no progress (a bar on a terminal,
    /// otherwise a line every 5 s, or every FLEXDYN_PROGRESS_INTERVAL s),
    /// no notes (the integrator and its tolerance, the initial state's
    /// projection), no warnings, and no error estimate (it would only be
    /// printed).
    #[arg(long)]
    pub quiet: bool,
}

/// A signal of time: a function, or a column of the inputs CSV (with the
/// column of its rates, if given).
enum Signal {
    Function(TimeFunction),
    Column {
        t: Vec<f64>,
        v: Vec<f64>,
        rate: Option<Vec<f64>>,
    },
}

impl Signal {
    /// Value and rate at `t`.
    fn at(&self, t: f64) -> (f64, f64) {
        match self {
            Signal::Function(f) => {
                let [v, d, _] = f.eval(t);
                (v, d)
            }
            Signal::Column { t: ts, v, rate } => {
                let (value, slope) = interpolate(ts, v, t);
                match rate {
                    Some(r) if (ts[0]..=ts[ts.len() - 1]).contains(&t) => {
                        (value, interpolate(ts, r, t).0)
                    }
                    Some(_) => (value, 0.0),
                    None => (value, slope),
                }
            }
        }
    }
}

/// The samples `v` at times `ts` interpolated linearly at `t` and held
/// constant outside: the value and the slope (zero outside).
fn interpolate(ts: &[f64], v: &[f64], t: f64) -> (f64, f64) {
    let k = ts.partition_point(|&x| x <= t);
    if k == 0 {
        (v[0], 0.0)
    } else if k == ts.len() {
        (v[k - 1], 0.0)
    } else {
        let slope = (v[k] - v[k - 1]) / (ts[k] - ts[k - 1]);
        (v[k - 1] + slope * (t - ts[k - 1]), slope)
    }
}

/// What drives one actuator: an open-loop input (zero if none) plus PD
/// feedback, if given.
#[derive(Default)]
struct Drive {
    open: Option<Signal>,
    pd: Option<Pd>,
}

/// PD gains on the coordinate an actuator drives, towards its target.
struct Pd {
    coordinate: usize,
    kp: f64,
    kd: f64,
    target: Signal,
}

/// Everything the run needs, checked.
struct Setup<'a> {
    model: &'a dyn DynModel,
    drives: Vec<Drive>,
    feedback: Option<crate::state_feedback::StateFeedback>,
    state: crate::eval::State,
    duration: f64,
    grid: Grid,
    max_steps: u64,
    integrator: Integrator,
    estimate: bool,
    quiet: bool,
    /// Indices of the markers in the rows.
    markers: Vec<usize>,
    /// The constraints' names, in the model's order.
    constraints: Vec<String>,
    /// The components whose forces switch with the state.
    switching: Vec<String>,
}

/// Run the command on the scenes of `compiled`.
pub fn run(args: &Args, compiled: &Compiled) -> Result<(), String> {
    let integrator = Integrator::of(args)?;
    let grid = Grid::of(args, &integrator)?;
    // The outputs' directories before the run, not after it.
    check_output(&args.csv)?;
    if let Some(plot) = &args.plot {
        check_output(plot)?;
    }
    let parsed = crate::codegen::Model::load(&args.scene).map_err(|e| e.to_string())?;
    super::tell_notes(&parsed, args.quiet);
    let mut model = compiled.load(&args.scene, &parsed.name, args.interpret)?;
    let state = initial_state(args, &parsed, model.as_mut())?;
    let model = &*model;
    let markers = chosen_markers(&args.markers, model)?;
    let columns = output_columns(model, &markers)?;
    let plotted: Vec<String> = match args.columns.is_empty() {
        true => model.coordinates().iter().map(|c| c.to_string()).collect(),
        false => args.columns.clone(),
    };
    if let Some(bad) = plotted.iter().find(|c| !columns.contains(c)) {
        return Err(format!(
            "--columns: no column `{bad}` (columns: {})",
            columns.join(", ")
        ));
    }
    let setup = Setup {
        model,
        drives: drives(args, &parsed, model)?,
        feedback: match &args.feedback {
            Some(path) => Some(crate::state_feedback::StateFeedback::read(path, model)?),
            None => None,
        },
        state,
        duration: args.duration,
        grid,
        max_steps: args.max_steps,
        integrator,
        estimate: !(args.no_error_estimate || args.quiet),
        quiet: args.quiet,
        markers,
        constraints: parsed.constraints.iter().map(|c| c.name.clone()).collect(),
        switching: parsed
            .switching_components()
            .into_iter()
            .map(str::to_owned)
            .collect(),
    };
    let mut outputs = OutputFiles::default();
    let mut csv = CsvWriter::create(&mut outputs, &args.csv, &columns)?;
    // The plotted columns (after `t`, column 0) of a bounded copy of the rows.
    let picked: Vec<usize> = plotted
        .iter()
        .filter_map(|c| columns.iter().position(|x| x == c))
        .collect();
    let mut kept = args.plot.as_ref().map(|_| Decimated::new(PLOT_ROWS));
    let mut picked_row = Vec::with_capacity(picked.len() + 1);
    let mut ranges = RangeWatch::new(&parsed, args.quiet);
    setup.run(&mut |row| {
        ranges.check(row);
        if let Some(kept) = &mut kept {
            picked_row.clear();
            picked_row.push(row[0]);
            picked_row.extend(picked.iter().map(|&k| row[k]));
            kept.push(&picked_row);
        }
        csv.row(row)
    })?;
    csv.finish()?;
    if let (Some(plot), Some(kept)) = (&args.plot, kept) {
        let rows = kept.rows();
        let series: Vec<Series> = plotted
            .iter()
            .enumerate()
            .map(|(k, c)| Series {
                label: c,
                points: rows.iter().map(|r| (r[0], r[k + 1])).collect(),
            })
            .collect();
        let title = format!("{} ({})", model.name(), args.integrator);
        let labels = Labels {
            title: &title,
            x: "t",
            y: "",
        };
        outputs.write(plot, |tmp| line_plot(tmp, &labels, &series))?;
    }
    outputs.commit()
}

/// The state to start from (not yet projected), with `--initial`'s runtime
/// parameters set on `model`.
fn initial_state(
    args: &Args,
    parsed: &crate::codegen::Model,
    model: &mut dyn DynModel,
) -> Result<crate::eval::State, String> {
    let Some(path) = &args.initial else {
        return Ok(crate::eval::State {
            q: parsed.coordinates.iter().map(|c| c.initial).collect(),
            qd: parsed
                .coordinates
                .iter()
                .map(|c| c.initial_velocity)
                .collect(),
            qdd: Vec::new(),
            tau: Vec::new(),
            t: 0.0,
            params: Default::default(),
        });
    };
    crate::eval::read_state(path, model)
}

/// `NAME=VALUE` split at the first `=`.
pub(super) fn assignment<'a>(option: &str, text: &'a str) -> Result<(&'a str, &'a str), String> {
    text.split_once('=')
        .map(|(n, v)| (n.trim(), v.trim()))
        .ok_or_else(|| format!("{option} `{text}`: expected NAME=VALUE"))
}

/// The drive of every actuator from `--input`, `--inputs`, `--pd`, `--target`.
fn drives(
    args: &Args,
    parsed: &crate::codegen::Model,
    model: &dyn DynModel,
) -> Result<Vec<Drive>, String> {
    let actuators = model.actuators();
    let coordinates = model.coordinates();
    let actuator = |option: &str, name: &str| {
        actuators.iter().position(|a| *a == name).ok_or_else(|| {
            format!(
                "{option}: unknown actuator `{name}` (actuators of `{}`: {})",
                model.name(),
                list(&actuators)
            )
        })
    };
    let function = |option: &str, text: &str| {
        TimeFunction::parse(parsed, text)
            .map(Signal::Function)
            .map_err(|e| format!("{option}: {e}"))
    };
    let mut drives: Vec<Drive> = actuators.iter().map(|_| Drive::default()).collect();
    // Where each actuator's open-loop input was given.
    let mut given: Vec<Option<String>> = vec![None; actuators.len()];
    let mut set = |j: usize, by: String, signal: Signal, drives: &mut Vec<Drive>| {
        if let Some(before) = &given[j] {
            return Err(format!(
                "actuator `{}` is given twice ({before} and {by})",
                actuators[j]
            ));
        }
        given[j] = Some(by);
        drives[j].open = Some(signal);
        Ok(())
    };
    for text in &args.inputs_expr {
        let (name, expr) = assignment("--input", text)?;
        let j = actuator(&format!("--input `{text}`"), name)?;
        let signal = function(&format!("--input {name}"), expr)?;
        set(j, format!("--input {name}"), signal, &mut drives)?;
    }
    let mut targets: Vec<Option<(String, Signal)>> = coordinates.iter().map(|_| None).collect();
    if let Some(path) = &args.inputs_csv {
        let table = Table::read(path)?;
        let file = path.display();
        let t = table.times(path)?;
        if table.columns.len() == 1 {
            return Err(format!(
                "{file}: no column besides `t`: give one per actuator driven (actuators: {}) \
                 or per coordinate targeted",
                list(&actuators)
            ));
        }
        // A coordinate's rate column, `<coordinate>_dot`.
        let rate_of = |name: &str| {
            let c = name.strip_suffix("_dot")?;
            coordinates.iter().position(|x| *x == c)
        };
        let mut rates = Vec::new();
        for name in table.columns.iter().filter(|c| *c != "t") {
            let v = table.column(name)?;
            let by = format!("column `{name}` of {file}");
            let signal = Signal::Column {
                t: t.clone(),
                v,
                rate: None,
            };
            if let Some(j) = actuators.iter().position(|a| a == name) {
                set(j, by, signal, &mut drives)?;
            } else if let Some(i) = coordinates.iter().position(|c| c == name) {
                targets[i] = Some((by, signal));
            } else if let Some(i) = rate_of(name) {
                rates.push((i, table.column(name)?));
            } else {
                return Err(format!(
                    "{file}: column `{name}` is neither an actuator nor a coordinate of `{}` \
                     nor a coordinate's rate `<coordinate>_dot` (actuators: {}; coordinates: \
                     {})",
                    model.name(),
                    list(&actuators),
                    list(&coordinates)
                ));
            }
        }
        for (i, r) in rates {
            match &mut targets[i] {
                Some((_, Signal::Column { rate, .. })) => *rate = Some(r),
                _ => {
                    return Err(format!(
                        "{file}: column `{}_dot` gives the rate of a target, but there is no \
                         column `{}` with the target",
                        coordinates[i], coordinates[i]
                    ))
                }
            }
        }
    }
    for text in &args.target {
        let (name, expr) = assignment("--target", text)?;
        let i = coordinates.iter().position(|c| *c == name).ok_or_else(|| {
            format!(
                "--target `{text}`: unknown coordinate `{name}` (coordinates: {})",
                list(&coordinates)
            )
        })?;
        if let Some((by, _)) = &targets[i] {
            return Err(format!(
                "target of `{name}` is given twice ({by} and --target)"
            ));
        }
        targets[i] = Some((
            "--target".into(),
            function(&format!("--target {name}"), expr)?,
        ));
    }
    let b = matrix(model.nq(), model.nu(), |o| model.actuator_map(o));
    for text in &args.pd {
        let (name, gains) = assignment("--pd", text)?;
        let j = actuator(&format!("--pd `{text}`"), name)?;
        if drives[j].pd.is_some() {
            return Err(format!("--pd: actuator `{name}` is given twice"));
        }
        let parsed_gains: Vec<f64> = gains
            .split(',')
            .map(|g| g.trim().parse::<f64>())
            .collect::<Result<_, _>>()
            .map_err(|e| format!("--pd `{text}`: gains must be numbers KP,KD: {e}"))?;
        let [kp, kd] = parsed_gains[..] else {
            return Err(format!("--pd `{text}`: expected two gains, KP,KD"));
        };
        if !(kp.is_finite() && kd.is_finite() && kp >= 0.0 && kd >= 0.0) {
            return Err(format!("--pd `{text}`: gains must be finite and >= 0"));
        }
        let driven: Vec<usize> = (0..b.nrows()).filter(|&i| b[(i, j)] != 0.0).collect();
        let [coordinate] = driven[..] else {
            return Err(format!(
                "--pd `{text}`: actuator `{name}` drives {} coordinates; PD feedback needs \
                 exactly one",
                driven.len()
            ));
        };
        let Some((_, target)) = targets[coordinate].take() else {
            return Err(format!(
                "--pd `{text}`: no target for coordinate `{}` (give --target {}=EXPR or a \
                 column `{}` in --inputs)",
                coordinates[coordinate], coordinates[coordinate], coordinates[coordinate]
            ));
        };
        drives[j].pd = Some(Pd {
            coordinate,
            kp,
            kd,
            target,
        });
    }
    if let Some((i, (by, _))) = targets
        .iter()
        .enumerate()
        .find_map(|(i, t)| t.as_ref().map(|t| (i, t)))
    {
        return Err(format!(
            "{by} sets a target for coordinate `{}`, but no --pd drives it",
            coordinates[i]
        ));
    }
    Ok(drives)
}

fn list(names: &[&str]) -> String {
    match names.is_empty() {
        true => "none".into(),
        false => names.join(", "),
    }
}

/// The indices of the markers `--markers` names (all when it names none,
/// none for `none`).
fn chosen_markers(names: &[String], model: &dyn DynModel) -> Result<Vec<usize>, String> {
    let all = model.markers();
    match names {
        [] => return Ok((0..all.len()).collect()),
        [none] if none == "none" => return Ok(Vec::new()),
        _ => {}
    }
    let mut chosen = Vec::with_capacity(names.len());
    for name in names {
        let k = all.iter().position(|m| m == name).ok_or_else(|| {
            format!(
                "--markers: scene `{}` has no marker `{name}` (markers: {})",
                model.name(),
                list(&all)
            )
        })?;
        if chosen.contains(&k) {
            return Err(format!("--markers: marker `{name}` is named twice"));
        }
        chosen.push(k);
    }
    Ok(chosen)
}

/// `t`, coordinates, `<name>_dot`, `T`, `V`, `drift`, then `<marker>_x`,
/// `_y`, `_z` of each chosen marker; an error when two columns would have
/// one name.
fn output_columns(model: &dyn DynModel, markers: &[usize]) -> Result<Vec<String>, String> {
    let mut columns = vec!["t".to_string()];
    columns.extend(model.coordinates().iter().map(|c| c.to_string()));
    columns.extend(model.coordinates().iter().map(|c| format!("{c}_dot")));
    columns.extend(["T", "V", "drift"].map(String::from));
    let names = model.markers();
    for &k in markers {
        for axis in ["x", "y", "z"] {
            let column = format!("{}_{axis}", names[k]);
            if columns.contains(&column) {
                return Err(format!(
                    "the column `{column}` of marker `{}` is also the name of another \
                     column; leave the marker out with --markers",
                    names[k]
                ));
            }
            columns.push(column);
        }
    }
    Ok(columns)
}

impl Setup<'_> {
    /// The simulation, on the model at its own size: its rows to `emit`, as
    /// they come.
    fn run(self, emit: Emit<'_>) -> Result<(), String> {
        let model = self.model;
        let (nq, nu) = (Dyn(model.nq()), Dyn(model.nu()));
        let mut state = StateOf::new(
            DVector::from_column_slice(&self.state.q),
            DVector::from_column_slice(&self.state.qd),
            self.state.t,
        );
        make_consistent(model, &mut state, self.quiet, &self.constraints)?;
        // Actuator j on coordinate joints[j]; actuators without PD get zero gains.
        let mut joints = DVector::<usize>::zeros(nu.0);
        let (mut kp, mut kd) = (DVector::zeros(nu.0), DVector::zeros(nu.0));
        for (j, d) in self.drives.iter().enumerate() {
            if let Some(pd) = &d.pd {
                (joints[j], kp[j], kd[j]) = (pd.coordinate, pd.kp, pd.kd);
            }
        }
        let drives = &self.drives;
        let reference = |t: f64| {
            let mut target = TargetOf {
                position: DVector::zeros(nu.0),
                velocity: DVector::zeros(nu.0),
                acceleration: DVector::zeros(nu.0),
            };
            for (j, d) in drives.iter().enumerate() {
                if let Some(pd) = &d.pd {
                    (target.position[j], target.velocity[j]) = pd.target.at(t);
                }
            }
            target
        };
        let pd =
            JointPdOf::of_sizes(nq, joints, kp, kd, reference).map_err(|e| format!("--pd: {e}"))?;
        let feedback = self.feedback.as_ref();
        let law = |q: &DVector<f64>, qd: &DVector<f64>, t: f64| match feedback {
            Some(f) => pd.input(q, qd, t) + f.input(q, qd),
            None => pd.input(q, qd, t),
        };
        let closed = Feedback::new(model, law);
        let open = FromFn(|t: f64| {
            let mut u = DVector::zeros(nu.0);
            for (j, d) in drives.iter().enumerate() {
                if let Some(s) = &d.open {
                    u[j] = s.at(t).0;
                }
            }
            u
        });
        let settings = match model.nc() {
            0 => StepSettings::default(),
            _ => StepSettings::with_projection(),
        };
        let run = Run {
            model,
            duration: self.duration,
            grid: self.grid,
            max_steps: self.max_steps,
            adaptive: matches!(self.integrator, Integrator::Adaptive { .. }),
            quiet: self.quiet,
            markers: &self.markers,
            constraints: &self.constraints,
            switching: &self.switching,
            emit,
        };
        // The companion of a fixed-step integrator of order `order`.
        let doubled = |order| {
            self.estimate.then_some(Companion::Doubled {
                order,
                dt: self.grid.step,
            })
        };
        match self.integrator {
            Integrator::Rk4 => run.go(with(Rk4::new(settings), doubled(4)), &closed, &open, state),
            Integrator::SemiImplicitEuler => run.go(
                with(SemiImplicitEuler::new(settings), doubled(1)),
                &closed,
                &open,
                state,
            ),
            Integrator::GaussLegendre { max_sweeps } => {
                let mut g = GaussLegendre4::new(settings);
                g.max_iterations = max_sweeps;
                run.go(with(g, doubled(4)), &closed, &open, state)
            }
            Integrator::GenAlpha {
                rho_inf,
                filter_start,
            } => {
                let config = GeneralizedAlphaConfig {
                    rho_inf,
                    filter_start,
                    ..GeneralizedAlphaConfig::default()
                };
                let g = GeneralizedAlphaOf::new(settings, config);
                run.go(with(g, doubled(2)), &closed, &open, state)
            }
            Integrator::Adaptive { tolerance } => {
                let atol = tolerance * 1e-2;
                if !self.quiet {
                    eprintln!(
                        "integrator: adaptive RK4, relative tolerance {tolerance:e}, absolute \
                         {atol:e}"
                    );
                }
                let g = |scale: f64| AdaptiveRk4 {
                    settings,
                    ..AdaptiveRk4::new(tolerance * scale, atol * scale)
                };
                let companion = self
                    .estimate
                    .then(|| (g(LOOSENED), Companion::Loosened { tolerance }));
                run.go((g(1.0), companion), &closed, &open, state)
            }
        }
    }
}

/// An integrator and, when there is a companion, a fresh copy of it for
/// the companion run.
fn with<G: Clone>(g: G, companion: Option<Companion>) -> (G, Option<(G, Companion)>) {
    let copy = companion.map(|c| (g.clone(), c));
    (g, copy)
}

/// The chosen integrator and its settings, checked.
#[derive(Clone, Copy, Debug)]
enum Integrator {
    Adaptive { tolerance: f64 },
    Rk4,
    SemiImplicitEuler,
    GaussLegendre { max_sweeps: u32 },
    GenAlpha { rho_inf: f64, filter_start: bool },
}

impl Integrator {
    /// `--integrator` and its options; an option the integrator would
    /// ignore is refused.
    fn of(args: &Args) -> Result<Integrator, String> {
        let name = args.integrator.as_str();
        if !INTEGRATORS.contains(&name) {
            return Err(format!(
                "unknown integrator `{name}` (integrators: {})",
                INTEGRATORS.join(", ")
            ));
        }
        let ignored = |option: &str, owner: &str, what: &str| {
            Err(format!(
                "{option} is {owner}'s {what}; `{name}` would ignore it (give --integrator \
                 {owner}, or leave {option} out)"
            ))
        };
        if args.tolerance.is_some() && name != "adaptive-rk4" {
            return ignored(
                "--tolerance",
                "adaptive-rk4",
                "error control (the others take fixed steps of --dt)",
            );
        }
        if args.rho_inf.is_some() && name != "gen-alpha" {
            return ignored("--rho-inf", "gen-alpha", "numerical damping");
        }
        if args.unfiltered_start && name != "gen-alpha" {
            return ignored("--unfiltered-start", "gen-alpha", "start");
        }
        if args.max_sweeps.is_some() && name != "gauss-legendre" {
            return ignored(
                "--max-sweeps",
                "gauss-legendre",
                "bound on its stage iteration",
            );
        }
        Ok(match name {
            "rk4" => Integrator::Rk4,
            "semi-implicit-euler" => Integrator::SemiImplicitEuler,
            "gauss-legendre" => {
                let max_sweeps = args
                    .max_sweeps
                    .unwrap_or(GaussLegendre4::<f64>::default().max_iterations);
                if !(1..=MAX_SWEEPS).contains(&max_sweeps) {
                    return Err(format!(
                        "--max-sweeps must lie in 1..={MAX_SWEEPS}, got {max_sweeps}"
                    ));
                }
                Integrator::GaussLegendre { max_sweeps }
            }
            "gen-alpha" => {
                let rho_inf = args
                    .rho_inf
                    .unwrap_or(GeneralizedAlphaConfig::<f64>::default().rho_inf);
                if !(0.0..=1.0).contains(&rho_inf) {
                    return Err(format!("--rho-inf must lie in [0, 1], got {rho_inf}"));
                }
                Integrator::GenAlpha {
                    rho_inf,
                    filter_start: !args.unfiltered_start,
                }
            }
            _ => {
                let tolerance = args.tolerance.unwrap_or(1e-8);
                if !(tolerance > 0.0 && tolerance < 1.0) {
                    return Err(format!("--tolerance must lie in (0, 1), got {tolerance}"));
                }
                Integrator::Adaptive { tolerance }
            }
        })
    }
}

/// The most sweeps `--max-sweeps` may ask of gauss-legendre (each sweep is
/// two acceleration solves).
const MAX_SWEEPS: u32 = 1000;

/// The time grid of a run: steps of `step` s (the last shortened to end at
/// the duration), a row every `every` of them and at the end.
#[derive(Clone, Copy, Debug)]
struct Grid {
    step: f64,
    steps: u64,
    every: u64,
}

impl Grid {
    /// The grid `--dt`, `--output-dt`, `--duration` and `--max-steps` ask
    /// of `integrator`: for the fixed-step integrators steps of `--dt` and a
    /// row every `--output-dt`; adaptive-rk4 chooses its own steps, so its
    /// grid is the output step (`--output-dt` or `--dt`, not both).
    fn of(args: &Args, integrator: &Integrator) -> Result<Grid, String> {
        let adaptive = matches!(integrator, Integrator::Adaptive { .. });
        let step = match (adaptive, args.dt, args.output_dt) {
            (true, Some(_), Some(_)) => {
                return Err(
                    "adaptive-rk4 chooses its own steps, so --dt is only its output \
                            step: give --output-dt or --dt, not both"
                        .into(),
                )
            }
            (true, None, Some(output)) => output,
            (_, dt, _) => dt.unwrap_or(0.01),
        };
        let steps = count(args.duration, step, Last::Shortened, args.max_steps)?;
        let every = match (adaptive, args.output_dt) {
            (false, Some(output)) => per_output("--output-dt", output, "--dt", step)?,
            _ => 1,
        };
        Ok(Grid { step, steps, every })
    }
}

/// Warns on stderr (unless quiet) the first time each coordinate, or its
/// rate, leaves the `range` (`velocity_range`) the scene declares for it:
/// where the model is meant to hold (a diverging motion, a linear model
/// taken beyond its validity). Once per coordinate and kind, with the time.
struct RangeWatch {
    /// The checks not yet warned of.
    checks: Vec<Option<RangeCheck>>,
}

/// One declared range: the row column, the coordinate's name, which range,
/// its bounds.
type RangeCheck = (usize, String, &'static str, [f64; 2]);

impl RangeWatch {
    /// The declared ranges of `scene`'s coordinates (none when `quiet`), for
    /// rows laid out as `t`, the coordinates, their rates.
    fn new(scene: &crate::codegen::Model, quiet: bool) -> RangeWatch {
        let n = scene.coordinates.len();
        let mut checks = Vec::new();
        for (i, c) in scene.coordinates.iter().enumerate().filter(|_| !quiet) {
            if let Some(r) = c.range {
                checks.push(Some((1 + i, c.name.clone(), "range", r)));
            }
            if let Some(r) = c.velocity_range {
                checks.push(Some((1 + n + i, c.name.clone(), "velocity_range", r)));
            }
        }
        RangeWatch { checks }
    }

    /// Checks one output row.
    fn check(&mut self, row: &[f64]) {
        for slot in &mut self.checks {
            if let Some((k, name, what, [lo, hi])) = slot {
                let x = row[*k];
                if !(x >= *lo && x <= *hi) {
                    eprintln!(
                        "warning: `{name}` left its declared {what} [{lo}, {hi}] at t = {} s \
                         (value {x:e}): the scene's model is meant to hold inside it",
                        Time(row[0])
                    );
                    *slot = None;
                }
            }
        }
    }
}

/// A state of a model of run-time size.
pub(super) type DynState = StateOf<f64, Dyn>;

/// Where the rows of a run go, as they come; an error stops the run.
type Emit<'e> = &'e mut dyn FnMut(&[f64]) -> Result<(), String>;

/// Project the initial state onto the constraints, reporting what changed
/// (unless `quiet`); an error when it cannot be done.
pub(super) fn make_consistent(
    model: &dyn DynModel,
    state: &mut DynState,
    quiet: bool,
    constraints: &[String],
) -> Result<(), String> {
    if model.nc() == 0 {
        return Ok(());
    }
    let before = state.clone();
    let report = project(model, state, &ProjectionConfig::default()).map_err(|e| {
        let why = singular_rows(model, constraints, &e, state);
        format!("the initial state cannot be made consistent with the constraints: {e}{why}")
    })?;
    if quiet {
        return Ok(());
    }
    let names = model.coordinates();
    for (what, suffix, a, b) in [
        ("position", "", &before.q, &state.q),
        ("velocity", "_dot", &before.qd, &state.qd),
    ] {
        for (i, name) in names.iter().enumerate() {
            if a[i] != b[i] {
                eprintln!(
                    "initial {what} projected onto the constraints: {name}{suffix} {:?} -> {:?} \
                     ({:+e})",
                    a[i],
                    b[i],
                    b[i] - a[i]
                );
            }
        }
    }
    if report.iterations > 0 || report.velocity_projected {
        eprintln!(
            "initial constraint residuals: position {:e} -> {:e}, velocity {:e} -> {:e}",
            report.before.position,
            report.after.position,
            report.before.velocity,
            report.after.velocity
        );
    }
    Ok(())
}

/// Where `e` is a singular constraint Jacobian: which constraints' rows
/// depend on the rows before them at `state` (empty when none do there:
/// the singular configuration was met inside the step).
fn singular_rows(
    model: &dyn DynModel,
    constraints: &[String],
    e: &flexdyn_runtime::Error,
    state: &DynState,
) -> String {
    if !matches!(e.kind, ErrorKind::SingularConstraintJacobian { .. }) {
        return String::new();
    }
    let q = state.q.as_slice();
    let jacobian = matrix(model.nc(), model.nq(), |o| {
        model.constraint_jacobian(q, state.t, o)
    });
    let rows: Vec<String> = crate::codegen::dependent_rows(&jacobian)
        .iter()
        .zip(constraints)
        .filter(|(d, _)| **d)
        .map(|(_, name)| format!("`{name}`"))
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    // Off the constraints as well: the iteration stalled where the rows
    // lose rank, short of a solution.
    let phi = vector(model.nc(), |o| model.constraints(q, state.t, o));
    let worst = phi.iamax();
    let meaning = match phi.get(worst) {
        Some(r) if r.abs() > 1e-6 => format!(
            ", where the residual of `{}` is {r:e}, not zero: the constraints have no solution \
             near this state, or meet only at a singular configuration",
            constraints.get(worst).map_or("?", |c| c.as_str())
        ),
        _ => ": a singular configuration of the mechanism".to_owned(),
    };
    format!(
        " (at t = {} s the Jacobian rows of {} vanish or are combinations of the rows before \
         them{meaning})",
        Time(state.t),
        rows.join(", ")
    )
}

/// The time loop and its output.
struct Run<'a, 'e> {
    model: &'a dyn DynModel,
    duration: f64,
    grid: Grid,
    /// Most accepted steps of the adaptive integrator.
    max_steps: u64,
    adaptive: bool,
    quiet: bool,
    /// Indices of the markers whose positions end the rows.
    markers: &'a [usize],
    /// The constraints' names.
    constraints: &'a [String],
    /// The components whose forces switch with the state.
    switching: &'a [String],
    emit: Emit<'e>,
}

impl Run<'_, '_> {
    /// The run of `integrator` from `state`, with its companion (when
    /// there is one) for the error estimate.
    fn go<G, M, I>(
        self,
        (mut integrator, companion): (G, Option<(G, Companion)>),
        model: &M,
        input: &I,
        mut state: DynState,
    ) -> Result<(), String>
    where
        G: IntegratorOf<Dyn, Dyn, Dyn>,
        M: Equations<Dyn, Dyn, Dyn>,
        I: InputOf<Dyn>,
    {
        let Grid { step, steps, every } = self.grid;
        let t0 = state.t;
        let end = t0 + self.duration;
        let at = |k: u64| (t0 + k as f64 * step).min(end);
        let quantities = || {
            let names = self.model.coordinates();
            let rates = names.iter().map(|c| format!("{c}_dot"));
            names.iter().map(|c| c.to_string()).chain(rates).collect()
        };
        let mut estimate =
            companion.map(|(g, c)| (g, state.clone(), ErrorEstimate::new(c, quantities())));
        let mut row = Vec::new();
        self.row(&state, &mut row);
        (self.emit)(&row)?;
        let mut progress = Progress::new(steps, "simulate", self.quiet).timed(t0, end);
        let mut taken = 0u64;
        for k in 1..=steps {
            let to = at(k);
            let h = to - state.t;
            let report = integrator
                .step(model, &mut state, input, h)
                .map_err(|e| self.failure(k, &state, h, e))?;
            state.t = to;
            if self.adaptive {
                // The report counts the accepted substeps.
                taken += u64::from(report.iterations);
                if taken > self.max_steps {
                    return Err(format!(
                        "adaptive-rk4 took {taken} steps to reach t = {} s of {} s, more than \
                         --max-steps {}; `--max-steps N` raises the limit (a larger --tolerance \
                         takes fewer steps)",
                        Time(state.t),
                        Time(end),
                        self.max_steps
                    ));
                }
            }
            if let Some((g, companion, e)) = &mut estimate {
                e.scale(state.q.iter().chain(state.qd.iter()).copied());
                // The companion steps to every second time of the grid.
                if k % 2 == 0 || k == steps {
                    let from = companion.t;
                    match g.step(model, companion, input, to - from) {
                        Ok(_) => {
                            companion.t = to;
                            let run = state.q.iter().chain(state.qd.iter()).copied();
                            let other = companion.q.iter().chain(companion.qd.iter()).copied();
                            e.compare(to, run, other);
                        }
                        Err(why) => {
                            // Told now; the run goes on without it.
                            e.fail(from, why.kind.to_string());
                            self.tell(e);
                            estimate = None;
                        }
                    }
                }
            }
            if k % every == 0 || k == steps {
                self.row(&state, &mut row);
                (self.emit)(&row)?;
            }
            progress.inc_to(state.t);
        }
        progress.finish();
        if let Some((_, _, e)) = &estimate {
            self.tell(e);
        }
        Ok(())
    }

    /// The error of step `k` (of size `h`, from `state`), with a hint where
    /// a coordinate has no mass, or where an implicit integrator's Newton
    /// iteration failed on a scene whose forces switch.
    fn failure(&self, k: u64, state: &DynState, h: f64, e: flexdyn_runtime::Error) -> String {
        let hint = match e.kind {
            ErrorKind::NewtonNotConverged { .. }
                if e.stage.is_none() && !self.switching.is_empty() =>
            {
                format!(
                    " (the forces of {} switch with the state: sign, step, abs, min or max of \
                     a coordinate or rate; at a switch the Newton iteration has no smooth \
                     Jacobian to follow, which smaller steps do not change: smooth the switch, \
                     docs/scene-format.md, Switches)",
                    self.switching
                        .iter()
                        .map(|c| format!("`{c}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }
            ErrorKind::MassMatrixNotPositiveDefinite { .. } => no_mass_hint(self.model, &e),
            _ => singular_rows(self.model, self.constraints, &e, state),
        };
        format!(
            "step {k} (t = {} s, dt = {} s): {e}{hint}",
            Time(state.t),
            Time(h)
        )
    }

    /// Prints the estimate's notes (unless quiet) and warnings.
    fn tell(&self, e: &ErrorEstimate) {
        let (notes, warnings) = e.report();
        for line in notes.iter().filter(|_| !self.quiet).chain(&warnings) {
            eprintln!("{line}");
        }
    }

    /// The output row of `s` into `row`.
    fn row(&self, s: &DynState, row: &mut Vec<f64>) {
        let (q, qd) = (s.q.as_slice(), s.qd.as_slice());
        row.clear();
        row.push(s.t);
        row.extend_from_slice(q);
        row.extend_from_slice(qd);
        row.push(self.model.kinetic_energy(q, qd, s.t));
        row.push(self.model.potential_energy(q, s.t));
        row.push(vector(self.model.nc(), |o| self.model.constraints(q, s.t, o)).norm());
        let (mut position, mut rotation) = ([0.0; 3], [0.0; 9]);
        for &k in self.markers {
            self.model
                .marker_pose(k, q, s.t, &mut position, &mut rotation);
            row.extend_from_slice(&position);
        }
    }
}
