//! `flexdyn inverse`: the actuator inputs, constraint forces and coordinates
//! of any scene along a prescribed motion of some of its coordinates
//! ([`crate::prescribed_motion`] has the method). Prescriptions are functions of `t`
//! in the scene's expression grammar ([`crate::codegen::TimeFunction`]),
//! given as `--prescribe NAME=EXPR` or in a motion file:
//!
//! ```toml
//! [prescribe]
//! px = "0.1*cos(2*t)"
//! ```
//!
//! or as sampled motions, a CSV (`--prescriptions P.csv`: a column `t`,
//! strictly increasing, and one column per prescribed coordinate, named
//! after it), interpolated by natural cubic splines ([`crate::spline`]) so
//! that rates and accelerations are continuous. The CSV's columns replace
//! the motion file's for the same coordinate, and a `--prescribe` replaces
//! both. The scene runs compiled in, or interpreted, at its own size.
//!
//! A prescribed name may also be a marker's world coordinate,
//! `<marker>_x`, `_y` or `_z` (task-space inverse dynamics). Where the
//! prescription and the constraints leave coordinates free (elastic ones),
//! the marker's coordinate is a servo output like a prescribed coordinate.
//! Where they fix every coordinate, the scene is interpreted with a
//! coordinate of that name and a constraint `<marker>_<axis>_servo` tying
//! the marker to it, so that the coordinates are solved from the
//! constraints as for any prescription.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::codegen::TimeFunction;
use crate::compiled::Compiled;
use crate::interpreted::InterpretedModel;
use crate::prescribed_motion::{
    solve, FreeRates, Method, Output, Prescribed, Problem, Sample, Sink, AXES,
};
use crate::progress::Progress;
use crate::spline::Spline;
use crate::steps::{count, Last, MAX_STEPS};
use crate::table::{check_output, read_input, CsvWriter, OutputFiles, Table};

/// Inverse dynamics of a scene along prescribed coordinates.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Scene file: a compiled-in scene runs compiled, any other interpreted.
    #[arg(long)]
    pub scene: PathBuf,
    /// Interpret the scene file even when a scene of its name is compiled in.
    #[arg(long)]
    pub interpret: bool,
    /// Duration, s (outputs at 0, dt, 2 dt, ..., duration).
    #[arg(long)]
    pub duration: f64,
    /// Output step, s (also the integration step when free coordinates are
    /// integrated). At most --max-steps steps of it fit in --duration.
    #[arg(long)]
    pub dt: f64,
    /// Largest number of output steps (--duration over --dt), refused
    /// before the run beyond it.
    #[arg(long, default_value_t = MAX_STEPS)]
    pub max_steps: u64,
    /// A prescribed coordinate: `NAME=EXPR`, a function of `t` and the
    /// scene's parameters (repeat for each); NAME may be a marker's world
    /// coordinate, `<marker>_x`, `_y` or `_z` (task space).
    #[arg(long = "prescribe", value_name = "NAME=EXPR")]
    pub prescribe: Vec<String>,
    /// Motion file (TOML, a `[prescribe]` table of `NAME = "EXPR"`).
    #[arg(long)]
    pub motion: Option<PathBuf>,
    /// Sampled prescriptions (CSV: `t`, then one column per prescribed
    /// coordinate, named after it), interpolated by natural cubic splines;
    /// the samples must cover `0..duration`.
    #[arg(long)]
    pub prescriptions: Option<PathBuf>,
    /// Newton's starting point: a state in the `eval` format
    /// (`{"q": [..], "qd": [..], "t": 0}`; only `q` is used). Default: the
    /// scene's `initial` values (0 where not given).
    #[arg(long)]
    pub initial: Option<PathBuf>,
    /// Initial rates of the coordinates the prescription and the
    /// constraints leave free (when they are integrated): of least kinetic
    /// energy, or zero on every coordinate the velocity constraints do not
    /// need (the first independent ones in the scene's order take the rates
    /// the constraints ask for).
    #[arg(long, value_enum, default_value_t = FreeRates::LeastEnergy)]
    pub free_rates: FreeRates,
    /// Output CSV: `t`, the actuators (an actuator named like a coordinate
    /// as `tau_<name>`), the coordinates, `lambda_<k>` for each constraint
    /// `k`. Written row by row as the run goes (a regular file appears
    /// whole when the run succeeds, or not at all; a device or FIFO gets
    /// the rows as they come).
    #[arg(long)]
    pub csv: PathBuf,
    /// Nothing on stderr unless it fails, as `simulate --quiet`: no
    /// progress (a bar on a terminal, otherwise a line every 5 s, or every
    /// FLEXDYN_PROGRESS_INTERVAL s).
    #[arg(long)]
    pub quiet: bool,
}

/// Run the command on the scenes of `compiled`.
pub fn run(args: &Args, compiled: &Compiled) -> Result<(), String> {
    check_output(&args.csv)?;
    let steps = count(args.duration, args.dt, Last::Within, args.max_steps)?;
    let mut scene = crate::codegen::Model::load(&args.scene).map_err(|e| e.to_string())?;
    super::tell_notes(&scene, args.quiet);
    let declared = scene.coordinates.len();
    let texts = given(
        &args.prescribe,
        args.motion.as_deref(),
        args.prescriptions.as_deref(),
    )?;
    // Prescribed marker coordinates where nothing is left free: the scene
    // with a coordinate and a constraint for each, interpreted.
    let axes = marker_axes(&scene, &texts);
    let determined = texts.len() + scene.constraints.len() >= scene.coordinates.len();
    let augmented = match axes.is_empty() || !determined {
        true => None,
        false => {
            if scene.sources.len() > 1 {
                return Err(format!(
                    "{}: a marker's coordinates can be prescribed in a full scene, not a \
                     derived one (prescribe them in its base scene)",
                    args.scene.display()
                ));
            }
            let text =
                with_marker_coordinates(read_input(&args.scene, "scene file")?, &scene, &axes);
            let source = crate::codegen::Source::new(&args.scene, text);
            scene = crate::codegen::Model::from_source(&source).map_err(|e| e.to_string())?;
            Some(source)
        }
    };
    let prescribed = resolve(&scene, texts)?;
    if let Some(path) = &args.prescriptions {
        let end = steps as f64 * args.dt;
        for (_, name, p) in &prescribed {
            if let Prescription::Sampled(spline) = p {
                let (a, b) = spline.span();
                if a > 0.0 || b < end {
                    return Err(format!(
                        "{}: the samples of `{name}` cover t = {a} .. {b} s, the run needs \
                         0 .. {end} s",
                        path.display(),
                    ));
                }
            }
        }
    }
    let mut guess = match &args.initial {
        Some(path) => initial_guess(path, declared)?,
        None => scene.coordinates[..declared]
            .iter()
            .map(|c| c.initial)
            .collect(),
    };
    guess.resize(scene.coordinates.len(), 0.0);
    let model: Box<dyn crate::dynamic::DynModel> = match &augmented {
        Some(source) => Box::new(InterpretedModel::from_source(source)?),
        None => compiled.load(&args.scene, &scene.name, args.interpret)?,
    };
    let coordinates: Vec<String> = scene.coordinates.iter().map(|c| c.name.clone()).collect();
    let constraints: Vec<String> = scene.constraints.iter().map(|c| c.name.clone()).collect();
    let actuators: Vec<String> = scene.actuators.iter().map(|a| a.name.clone()).collect();
    let mut outputs = OutputFiles::default();
    let columns = Job::columns(&coordinates, &constraints, &actuators);
    let mut csv = CsvWriter::create(&mut outputs, &args.csv, &columns)?;
    let mut progress =
        Progress::new(steps + 1, "inverse", args.quiet).timed(0.0, steps as f64 * args.dt);
    let mut row = Vec::with_capacity(columns.len());
    let mut sink = |s: &Sample<'_>| {
        row.clear();
        row.push(s.t);
        row.extend_from_slice(s.tau);
        row.extend_from_slice(s.q);
        row.extend_from_slice(s.lambda);
        progress.inc_to(s.t);
        csv.row(&row)
    };
    let job = Job {
        coordinates,
        constraints,
        actuators,
        prescribed,
        guess,
        dt: args.dt,
        steps: usize::try_from(steps).map_err(|_| format!("{steps} steps: too many here"))?,
        free_rates: args.free_rates,
        sink: &mut sink,
    };
    job.solve(model.as_ref())?;
    progress.finish();
    csv.finish()?;
    outputs.commit()
}

/// A prescribed motion of one coordinate.
pub enum Prescription {
    /// An expression of `t`.
    Function(TimeFunction),
    /// A spline through a CSV column.
    Sampled(Spline),
}

impl Prescription {
    /// Value, rate and acceleration at `t`.
    pub fn eval(&self, t: f64) -> [f64; 3] {
        match self {
            Prescription::Function(f) => f.eval(t),
            Prescription::Sampled(s) => s.eval(t),
        }
    }
}

/// What a prescription is given as.
enum Source {
    Text(String),
    Samples(Vec<f64>, Vec<f64>),
}

/// The prescriptions as given: by name, what each is and where it was
/// given.
type Given = BTreeMap<String, (Source, String)>;

/// The prescriptions of the motion file, then of the CSV, then of the
/// command line (each replacing the previous for the same name), by name.
fn given(
    prescribe: &[String],
    motion: Option<&Path>,
    samples: Option<&Path>,
) -> Result<Given, String> {
    let mut texts = Given::new();
    if let Some(path) = motion {
        let where_ = path.display().to_string();
        let text = read_input(path, "motion file")?;
        let file: toml::Table = text
            .parse()
            .map_err(|e| format!("motion file {where_}: {e}"))?;
        if let Some(key) = file.keys().find(|k| *k != "prescribe") {
            return Err(format!(
                "motion file {where_}: unknown key `{key}` (only a `[prescribe]` table)"
            ));
        }
        let table = file
            .get("prescribe")
            .and_then(toml::Value::as_table)
            .ok_or_else(|| format!("motion file {where_}: no `[prescribe]` table"))?;
        for (name, value) in table {
            let expr = value.as_str().ok_or_else(|| {
                format!("motion file {where_}: `prescribe.{name}` must be a string expression")
            })?;
            let at = format!("motion file {where_}, `prescribe.{name}`");
            texts.insert(name.clone(), (Source::Text(expr.to_owned()), at));
        }
    }
    if let Some(path) = samples {
        let table = Table::read(path)?;
        let t = table.times(path)?;
        for name in table.columns.iter().filter(|c| *c != "t") {
            let at = format!("column `{name}` of {}", path.display());
            let values = Source::Samples(t.clone(), table.column(name)?);
            texts.insert(name.clone(), (values, at));
        }
    }
    let mut seen = Vec::new();
    for item in prescribe {
        let (name, expr) = item
            .split_once('=')
            .ok_or_else(|| format!("--prescribe `{item}`: expected NAME=EXPR"))?;
        let name = name.trim();
        if seen.contains(&name) {
            return Err(format!("--prescribe: `{name}` is prescribed twice"));
        }
        seen.push(name);
        let at = format!("--prescribe {name}");
        texts.insert(name.to_owned(), (Source::Text(expr.to_owned()), at));
    }
    Ok(texts)
}

/// Whether `name` is a marker's coordinate of `scene` (`<marker>_x`, `_y`,
/// `_z`) rather than a coordinate: the marker's index and the axis.
fn marker_axis(scene: &crate::codegen::Model, name: &str) -> Option<Output> {
    if scene.coordinates.iter().any(|c| c.name == name) {
        return None;
    }
    let (marker, axis) = name.rsplit_once('_')?;
    let axis = AXES
        .iter()
        .position(|a| axis.len() == 1 && axis.starts_with(*a))?;
    let marker = scene.markers.iter().position(|m| m.name == marker)?;
    Some(Output::Marker { marker, axis })
}

/// The prescribed names that are marker coordinates, as outputs.
fn marker_axes(scene: &crate::codegen::Model, given: &Given) -> Vec<Output> {
    given
        .keys()
        .filter_map(|name| marker_axis(scene, name))
        .collect()
}

/// The scene's text with a coordinate `<marker>_<axis>` per prescribed
/// marker coordinate and a constraint tying the marker to it (task-space
/// inverse dynamics as prescribed coordinates: the constraint's multiplier
/// is zero, the coordinate massless).
fn with_marker_coordinates(
    mut text: String,
    scene: &crate::codegen::Model,
    axes: &[Output],
) -> String {
    for o in axes {
        if let Output::Marker { marker, axis } = *o {
            let (marker, axis) = (&scene.markers[marker].name, AXES[axis]);
            text.push_str(&format!(
                "\n[[coordinates]]\nname = \"{marker}_{axis}\"\n\n[[constraints]]\n\
                 name = \"{marker}_{axis}_servo\"\nexpression = \"{marker}.{axis} - {marker}_{axis}\"\n"
            ));
        }
    }
    text
}

/// The prescriptions resolved against `scene`'s coordinates and markers,
/// as outputs with their names and motions, in output order. Errors name
/// the coordinate (listing the valid ones and the markers), the expression
/// and where in it, or the file and column.
fn resolve(
    scene: &crate::codegen::Model,
    texts: Given,
) -> Result<Vec<(Output, String, Prescription)>, String> {
    let names: Vec<&str> = scene.coordinates.iter().map(|c| c.name.as_str()).collect();
    let markers: Vec<&str> = scene.markers.iter().map(|m| m.name.as_str()).collect();
    let mut out = Vec::with_capacity(texts.len());
    for (name, (source, at)) in texts {
        let output = names
            .iter()
            .position(|n| *n == name)
            .map(Output::Coordinate)
            .or_else(|| marker_axis(scene, &name))
            .ok_or_else(|| {
                let markers = match markers.is_empty() {
                    true => String::new(),
                    false => format!(
                        "; or a marker's coordinate `<marker>_x`, `_y`, `_z` of its markers: {}",
                        markers.join(", ")
                    ),
                };
                format!(
                    "{at}: `{name}` is not a coordinate of scene `{}` (its coordinates: {}{markers})",
                    scene.name,
                    names.join(", ")
                )
            })?;
        let f = match source {
            Source::Text(expr) => Prescription::Function(
                TimeFunction::parse(scene, &expr).map_err(|e| format!("{at}: {e}"))?,
            ),
            Source::Samples(t, y) => {
                Prescription::Sampled(Spline::new(t, y).map_err(|e| format!("{at}: {e}"))?)
            }
        };
        out.push((output, name, f));
    }
    out.sort_by_key(|(o, _, _)| *o);
    Ok(out)
}

/// `q` of a state file in the `eval` format, checked against the scene.
fn initial_guess(path: &Path, nq: usize) -> Result<Vec<f64>, String> {
    let text = read_input(path, "state file")?;
    let state: crate::eval::State =
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
    if state.q.len() != nq || state.q.iter().any(|x| !x.is_finite()) {
        return Err(format!(
            "{}: `q` must hold {nq} finite values (one per coordinate), got {:?}",
            path.display(),
            state.q
        ));
    }
    Ok(state.q)
}

/// The inverse-dynamics problem of a scene.
struct Job<'a> {
    coordinates: Vec<String>,
    constraints: Vec<String>,
    actuators: Vec<String>,
    prescribed: Vec<(Output, String, Prescription)>,
    guess: Vec<f64>,
    dt: f64,
    steps: usize,
    free_rates: FreeRates,
    /// Where the rows go.
    sink: Sink<'a>,
}

impl Job<'_> {
    /// The CSV's columns: `t`, the actuators, the coordinates, the multipliers: unique names,
    /// an actuator named like a coordinate or a multiplier (a URDF import
    /// names both after the joint) as `tau_<name>` (prefixed again while
    /// that is taken too).
    fn columns(
        coordinates: &[String],
        constraints: &[String],
        actuators: &[String],
    ) -> Vec<String> {
        let others: Vec<String> = std::iter::once("t".to_owned())
            .chain(coordinates.iter().cloned())
            .chain((0..constraints.len()).map(|k| format!("lambda_{k}")))
            .collect();
        let mut columns = vec!["t".to_owned()];
        for a in actuators {
            let mut name = a.clone();
            while others.contains(&name) || columns.contains(&name) {
                name = format!("tau_{name}");
            }
            columns.push(name);
        }
        columns.extend(others.into_iter().skip(1));
        columns
    }
}

impl Job<'_> {
    fn solve(self, model: &dyn crate::dynamic::DynModel) -> Result<Method, String> {
        let motions: Vec<_> = self
            .prescribed
            .iter()
            .map(|(_, _, f)| move |t: f64| f.eval(t))
            .collect();
        let problem = Problem {
            prescribed: self
                .prescribed
                .iter()
                .zip(&motions)
                .map(|((output, _, _), motion)| Prescribed {
                    output: *output,
                    motion,
                })
                .collect(),
            coordinates: self.coordinates,
            constraints: self.constraints,
            actuators: self.actuators,
            guess: self.guess,
            dt: self.dt,
            steps: self.steps,
            free_rates: self.free_rates,
        };
        solve(model, &problem, self.sink)
    }
}
