//! The generator's entry point: a builder that turns scene files into Rust
//! modules, all or nothing ([`crate::files`]), writing only files whose
//! content changed. Each scene goes through the stages in order: load,
//! model, reduce, derive, prune, then schedule and emit ([`generate_scene`]);
//! [`Model`] offers the first stages to callers that want the symbolic model
//! itself.
//!
//! ```no_run
//! flexdyn_codegen::Builder::new()
//!     .scenes_in("scenes")
//!     .out_dir("generated")
//!     .generate()
//!     .unwrap();
//! ```

use std::fmt;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use quote::quote;

use crate::checks::{energy_signs, f32_literals, largest_component, massless_coordinates};
use crate::derive::{derive, Equations};
use crate::emit::{emit, struct_name, CoefficientPerturbation, FunctionReport};
use crate::emit_c::CInterface;
use crate::error::{Error, Source};
use crate::files::OutputFiles;
use crate::load::{load, resolve, LoadedScene};
use crate::model::{build, overflow_message, Model, Precision};
use crate::prune::prune;
use crate::reduce;
use crate::redundancy::drop_redundant;
use crate::resolution::{stiffness_spread, F32_MAX_STIFFNESS_SPREAD};
use crate::schedule::{functions, OpCount};
use crate::solve::forward_dynamics;

/// The runtime crate's path in emitted code, unless the builder says
/// otherwise.
const DEFAULT_RUNTIME_PATH: &str = "flexdyn_runtime";

/// Stages 2 and 3: the symbolic model of a loaded scene, with a derived
/// scene's reductions applied.
fn model_of(scene: LoadedScene) -> Result<Model, Error> {
    let model = build(&scene)?;
    let mut model = match &scene.derived {
        Some((source, def)) => reduce::apply(model, def, source)?,
        None => model,
    };
    drop_redundant(&mut model)
        .map_err(|u| scene.source.error_at(u.at, Some(&u.context), u.message))?;
    Ok(model)
}

impl Model {
    /// Load a scene file into its symbolic model (a derived scene loads its
    /// base and applies its reductions).
    pub fn load(path: &Path) -> Result<Model, Error> {
        model_of(load(path)?)
    }

    /// [`Model::load`] from a scene file's text; a derived scene's base is
    /// read from the directory of `source`'s path.
    pub fn from_source(source: &Source) -> Result<Model, Error> {
        model_of(resolve(source.clone())?)
    }

    /// Stages 4 and 5: the equations of motion, derived and, when the scene
    /// asks for it, pruned, with the forward dynamics of an unconstrained
    /// scene solved on them. Adds the derived terms to [`Model::graph`].
    ///
    /// Refuses a derivation whose constants overflow `f64` (naming the
    /// component with the largest constant) and `energy` components whose
    /// kinetic energy or dissipation decreases along a velocity.
    pub fn equations(&mut self) -> Result<Equations, Error> {
        let file = self.sources.first().cloned().unwrap_or_default();
        let error = |context: &str, message: String| Error::unplaced(&file, Some(context), message);
        let mut eq = derive(self).map_err(|e| error(&e.context, e.message))?;
        prune(self, &mut eq);
        if self.graph.take_overflow() {
            let what = match largest_component(self) {
                Some((c, k)) => format!(
                    "deriving the equations of motion (the largest constant, {k:e}, is component \
                     `{}`'s)",
                    c.name
                ),
                None => "deriving the equations of motion".to_owned(),
            };
            return Err(error("the equations of motion", overflow_message(&what)));
        }
        energy_signs(self).map_err(|f| error(&f.context, f.message))?;
        if let Some(note) = massless_coordinates(self, &eq) {
            self.notes.push(note);
        }
        // A mass matrix singular by construction (a coordinate that moves
        // no mass: a zero pivot, `1 / 0`) has no forward dynamics to
        // generate; the runtime's factorisation reports it.
        forward_dynamics(&mut self.graph, &mut eq);
        if self.graph.take_overflow() {
            eq.forward_dynamics = None;
            eq.forward_dynamics_derivatives = None;
        }
        Ok(eq)
    }
}

/// A scene turned into Rust source, not yet written anywhere.
#[derive(Debug, Clone)]
pub struct Generated {
    /// Scene name (module and file name).
    pub name: String,
    /// The scene file.
    pub scene: PathBuf,
    /// Every file read for it (a derived scene and its base).
    pub sources: Vec<PathBuf>,
    /// Formatted module source.
    pub source: String,
    /// Numbers of coordinates, constraints and actuators.
    pub dims: (usize, usize, usize),
    /// The scalar type of the module.
    pub precision: Precision,
    /// Operation counts per emitted function.
    pub functions: Vec<FunctionReport>,
    /// The C header of the module's `extern "C"` wrappers, when the builder
    /// asked for the C interface ([`Builder::c_interface`]).
    pub c_header: Option<String>,
    /// Time spent parsing, deriving and emitting.
    pub elapsed: Duration,
    /// What the stages changed that a user should know ([`Model::notes`]).
    pub notes: Vec<String>,
}

impl Generated {
    /// The name of the module's model type (`Ur5` for the scene `ur5`).
    pub fn struct_name(&self) -> String {
        struct_name(&self.name)
    }

    /// Operations of all emitted functions.
    pub fn total_ops(&self) -> OpCount {
        let mut t = OpCount::default();
        for f in &self.functions {
            t += f.ops;
        }
        t
    }
}

impl fmt::Display for Generated {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (nq, nc, nu) = self.dims;
        write!(
            f,
            "{}: {nq} coordinates, {nc} constraints, {nu} actuators; {} ops ({}) in {:.1} ms",
            self.name,
            self.total_ops().total(),
            self.total_ops(),
            self.elapsed.as_secs_f64() * 1e3
        )?;
        for note in &self.notes {
            write!(f, "\n  note: {note}")?;
        }
        Ok(())
    }
}

/// Generate the Rust module of one scene file, in memory, for the runtime
/// crate at its default path `flexdyn_runtime`.
pub fn generate_scene(path: &Path) -> Result<Generated, Error> {
    let runtime = runtime_path(DEFAULT_RUNTIME_PATH)?;
    generate_perturbed(
        path,
        &Options {
            runtime: &runtime,
            perturbations: &[],
            c_interface: false,
            precision: None,
            allow_unresolved_f32: false,
        },
    )
}

/// The runtime path as a Rust path: `a::b`, `::a::b` or `crate::a`, without
/// generic arguments.
fn runtime_path(text: &str) -> Result<syn::Path, Error> {
    let error = |why: String| {
        Error::unplaced(
            PathBuf::new(),
            Some("Builder::runtime_path"),
            format!(
                "`{text}` is not a path to the runtime crate (such as `flexdyn_runtime`, \
                 `crate::rt` or `::my_rt`): {why}"
            ),
        )
    };
    let path: syn::Path = syn::parse_str(text).map_err(|e| error(e.to_string()))?;
    if path.segments.iter().any(|s| !s.arguments.is_none()) {
        return Err(error("generic arguments are not allowed".into()));
    }
    Ok(path)
}

/// How a scene is emitted.
struct Options<'a> {
    /// The runtime crate's path in emitted code.
    runtime: &'a syn::Path,
    /// Test-only perturbations of coefficients.
    perturbations: &'a [CoefficientPerturbation],
    /// Whether to add the C interface.
    c_interface: bool,
    /// The precision, overriding the scene's.
    precision: Option<Precision>,
    /// Generate `f32` even beyond its stiffness spread.
    allow_unresolved_f32: bool,
}

/// [`generate_scene`] with `options`, applying the perturbation among
/// `options.perturbations` that names this scene (an error if it finds no
/// such coefficient).
fn generate_perturbed(path: &Path, options: &Options) -> Result<Generated, Error> {
    let start = Instant::now();
    let mut model = Model::load(path)?;
    if let Some(p) = options.precision {
        model.precision = p;
    }
    if options.c_interface && model.precision != Precision::F64 {
        return Err(Error::unplaced(
            path.to_path_buf(),
            None,
            "the C interface is generated for f64 models only (the scene or the builder asks for f32)",
        ));
    }
    let (runtime, perturbations) = (options.runtime, options.perturbations);
    let eq = model.equations()?;
    if model.precision == Precision::F32 && !options.allow_unresolved_f32 {
        check_f32_resolution(path, &model, &eq)?;
    }
    let perturbation = perturbations.iter().find(|c| c.scene == model.name);
    let functions = functions(&model, &eq);
    if model.precision == Precision::F32 {
        f32_literals(&functions)
            .map_err(|f| Error::unplaced(path.to_path_buf(), Some(&f.context), f.message))?;
    }
    let c = options
        .c_interface
        .then(|| CInterface::new(&model, &functions));
    let (emitted, applied) = emit(&model, functions, runtime, perturbation);
    if let (Some(c), false) = (perturbation, applied) {
        return Err(Error::unplaced(
            path.to_path_buf(),
            None,
            format!(
                "cannot perturb coefficient {} of `{}`: the function does not exist or has fewer coefficients",
                c.index, c.function
            ),
        ));
    }
    Ok(Generated {
        name: model.name.clone(),
        scene: path.to_path_buf(),
        sources: model.sources.clone(),
        source: match &c {
            Some(c) => emitted.source + &c.rust(runtime),
            None => emitted.source,
        },
        c_header: c.map(|c| c.header()),
        dims: (model.nq(), model.constraints.len(), model.actuators.len()),
        precision: model.precision,
        functions: emitted.functions,
        elapsed: start.elapsed(),
        notes: model.notes,
    })
}

/// Refuses an `f32` module for a scene whose stiffness spread exceeds
/// [`F32_MAX_STIFFNESS_SPREAD`] (see [`crate::resolution`]).
fn check_f32_resolution(path: &Path, model: &Model, eq: &Equations) -> Result<(), Error> {
    let Some(s) = stiffness_spread(model, eq) else {
        return Ok(());
    };
    if s.spread <= F32_MAX_STIFFNESS_SPREAD {
        return Ok(());
    }
    Err(Error::unplaced(
        path.to_path_buf(),
        Some("precision"),
        format!(
            "scene `{}` cannot be computed in f32: its stiffness spread (|eigenvalues| of \
             M^-1 d(dV/dq)/dq at rest, over the declared ranges' sample states) is {:.3e}, \
             from the stiffest mode at {:.3e} 1/s^2 (mostly {}) to the softest at {:.3e} \
             1/s^2 (mostly {}), beyond f32's limit 1/eps = {:.3e}: the soft modes' forces are \
             below the rounding of the stiff ones, and the stiff coordinates' deflections below \
             the resolution of the positions. Generate it in f64, or remove or stiffen the \
             stiffest coordinates (a derived scene); to generate f32 anyway: \
             `flexdyn generate --allow-unresolved-f32` or Builder::allow_unresolved_f32(true)",
            model.name,
            s.spread,
            s.stiff.0,
            s.stiff.1.join(", "),
            s.soft.0,
            s.soft.1.join(", "),
            F32_MAX_STIFFNESS_SPREAD
        ),
    ))
}

/// Configures and runs the generator.
#[derive(Debug, Clone, Default)]
pub struct Builder {
    scenes: Vec<PathBuf>,
    dirs: Vec<PathBuf>,
    out_dir: Option<PathBuf>,
    rerun_if_changed: bool,
    index: Option<Index>,
    runtime_path: Option<String>,
    perturbations: Vec<CoefficientPerturbation>,
    c_interface: bool,
    precision: Option<Precision>,
    allow_unresolved_f32: bool,
}

/// Settings of the index module.
#[derive(Debug, Clone)]
struct Index {
    file: String,
    trait_path: String,
    wrapper: String,
}

/// What a run produced.
#[derive(Debug, Clone)]
pub struct Report {
    /// Every scene, in order.
    pub scenes: Vec<Generated>,
    /// Files written (those whose content changed).
    pub written: Vec<PathBuf>,
}

impl Builder {
    /// A builder with no scenes.
    pub fn new() -> Builder {
        Builder::default()
    }

    /// Add a scene file.
    pub fn scene(mut self, path: impl Into<PathBuf>) -> Builder {
        self.scenes.push(path.into());
        self
    }

    /// Add every `*.toml` file of a directory (sorted by name).
    pub fn scenes_in(mut self, dir: impl Into<PathBuf>) -> Builder {
        self.dirs.push(dir.into());
        self
    }

    /// Where to write the modules; defaults to `$OUT_DIR`.
    pub fn out_dir(mut self, dir: impl Into<PathBuf>) -> Builder {
        self.out_dir = Some(dir.into());
        self
    }

    /// Print `cargo:rerun-if-changed` for every input (for build scripts).
    pub fn emit_rerun_if_changed(mut self, yes: bool) -> Builder {
        self.rerun_if_changed = yes;
        self
    }

    /// Also write an index module `file` that declares one module per scene
    /// (each `include!`s its file), `SCENES` with their names, and a function
    /// `model(name)` returning the scene's default model as
    /// `Box<dyn trait_path>` built by `wrapper::<_, NQ, NC, NU>(model)`.
    /// Both paths (for example `crate::dynamic::DynModel` and
    /// `crate::dynamic::erase`) come from the build script, not from scenes.
    pub fn index(
        mut self,
        file: impl Into<String>,
        trait_path: impl Into<String>,
        wrapper: impl Into<String>,
    ) -> Builder {
        self.index = Some(Index {
            file: file.into(),
            trait_path: trait_path.into(),
            wrapper: wrapper.into(),
        });
        self
    }

    /// The path by which emitted code names the runtime crate
    /// (`flexdyn-runtime`): its `Model` trait, `math` and `nalgebra`
    /// re-export. Defaults to `flexdyn_runtime`; give `crate::rt` or
    /// `::my_rt` where the runtime is re-exported or renamed. Generation
    /// fails with an error if it is not a Rust path.
    pub fn runtime_path(mut self, path: impl Into<String>) -> Builder {
        self.runtime_path = Some(path.into());
        self
    }

    /// Also emit the C interface: `extern "C"` wrappers of every generated
    /// function and of the runtime's inverse dynamics in each module
    /// (`#[no_mangle]`, named `<scene>_<function>`, caller-owned arrays,
    /// status codes instead of panics), and the header `<scene>.h` beside
    /// it. The wrappers need `unsafe` (raw pointers); the default module has
    /// none.
    pub fn c_interface(mut self, yes: bool) -> Builder {
        self.c_interface = yes;
        self
    }

    /// Generate every scene in `precision`, whatever its scene file says
    /// (scene key `precision`, default `f64`). An `f32` module implements
    /// the runtime's `Model<NQ, NC, NU, f32>`; the index module and the C
    /// interface are for `f64` models only, so asking for either with `f32`
    /// is an error.
    ///
    /// An `f32` module is refused (an error naming the spread and the
    /// modes) for a scene whose linearised stiffness spreads beyond `1 /
    /// eps_32 = 8.4e6` (see docs/embedded.md, "f32 or f64"), unless
    /// [`Builder::allow_unresolved_f32`].
    pub fn precision(mut self, precision: Precision) -> Builder {
        self.precision = Some(precision);
        self
    }

    /// Generate `f32` modules even for scenes whose stiffness spread `f32`
    /// does not resolve (see [`Builder::precision`]): for a user who has
    /// checked the f32 results that matter to them against f64 (the
    /// flexible parallel robot's torques along the paper's circle are
    /// within 1e-5 of f64 at 2 rad/s, 5 ms; its joint deflections are not
    /// resolved at all).
    pub fn allow_unresolved_f32(mut self, yes: bool) -> Builder {
        self.allow_unresolved_f32 = yes;
        self
    }

    /// Test only: multiply coefficient `index` of the emitted function
    /// `function` of scene `scene` by `1 + relative`, to prove that a
    /// validation catches a wrong term in generated code. The module's header
    /// says so; generation fails if the scene is not generated or the
    /// coefficient does not exist.
    #[cfg(any(test, feature = "test-hooks"))]
    #[doc(hidden)]
    pub fn perturb_coefficient(
        mut self,
        scene: &str,
        function: &str,
        index: usize,
        relative: f64,
    ) -> Builder {
        self.perturbations.push(CoefficientPerturbation {
            scene: scene.to_owned(),
            function: function.to_owned(),
            index,
            relative,
        });
        self
    }

    /// All scene files, explicit ones first, then each directory's sorted.
    pub fn scene_files(&self) -> Result<Vec<PathBuf>, Error> {
        let mut files = self.scenes.clone();
        for dir in &self.dirs {
            let io = |e: std::io::Error| {
                Error::unplaced(
                    dir.clone(),
                    None,
                    format!("cannot list scene directory: {e}"),
                )
            };
            let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
                .map_err(io)?
                .collect::<Result<Vec<_>, _>>()
                .map_err(io)?
                .into_iter()
                .map(|e| e.path())
                .filter(|p| p.extension().is_some_and(|x| x == "toml"))
                .collect();
            found.sort();
            files.extend(found);
        }
        Ok(files)
    }

    /// Generate every scene; write nothing unless all succeed.
    pub fn generate(self) -> Result<Report, Error> {
        if self.rerun_if_changed {
            for dir in &self.dirs {
                println!("cargo:rerun-if-changed={}", dir.display());
            }
        }
        let runtime = runtime_path(self.runtime_path.as_deref().unwrap_or(DEFAULT_RUNTIME_PATH))?;
        let files = self.scene_files()?;
        if self.rerun_if_changed {
            for f in &files {
                println!("cargo:rerun-if-changed={}", f.display());
            }
        }
        let mut scenes: Vec<Generated> = Vec::new();
        for f in &files {
            let g = generate_perturbed(
                f,
                &Options {
                    runtime: &runtime,
                    perturbations: &self.perturbations,
                    c_interface: self.c_interface,
                    precision: self.precision,
                    allow_unresolved_f32: self.allow_unresolved_f32,
                },
            )?;
            if self.rerun_if_changed {
                for s in g.sources.iter().filter(|s| !files.contains(s)) {
                    println!("cargo:rerun-if-changed={}", s.display());
                }
            }
            if let Some(other) = scenes.iter().find(|s| s.name == g.name) {
                return Err(Error::unplaced(
                    f.clone(),
                    None,
                    format!(
                        "scene name `{}` is already used by {}",
                        g.name,
                        other.scene.display()
                    ),
                ));
            }
            scenes.push(g);
        }
        if let Some(c) = self
            .perturbations
            .iter()
            .find(|c| !scenes.iter().any(|s| s.name == c.scene))
        {
            return Err(Error::unplaced(
                PathBuf::new(),
                None,
                format!("cannot perturb scene `{}`: it is not generated", c.scene),
            ));
        }
        let out_dir = match &self.out_dir {
            Some(d) => d.clone(),
            None => std::env::var_os("OUT_DIR").map(PathBuf::from).ok_or_else(|| Error::unplaced(PathBuf::new(), None, "no output directory: set one with Builder::out_dir or run from a build script"))?,
        };
        let mut outputs: Vec<(PathBuf, String)> = scenes
            .iter()
            .map(|s| (out_dir.join(format!("{}.rs", s.name)), s.source.clone()))
            .collect();
        outputs.extend(scenes.iter().filter_map(|s| {
            let h = s.c_header.clone()?;
            Some((out_dir.join(format!("{}.h", s.name)), h))
        }));
        if let (Some(index), Some(s)) = (
            &self.index,
            scenes.iter().find(|s| s.precision != Precision::F64),
        ) {
            return Err(Error::unplaced(
                s.scene.clone(),
                None,
                format!(
                    "scene `{}` is generated in {}: the index module `{}` needs f64 models",
                    s.name,
                    s.precision.rust_type(),
                    index.file
                ),
            ));
        }
        if let Some(index) = &self.index {
            let text = index_source(&scenes, index)
                .map_err(|message| Error::unplaced(PathBuf::from(&index.file), None, message))?;
            outputs.push((out_dir.join(&index.file), text));
        }
        std::fs::create_dir_all(&out_dir).map_err(|e| {
            Error::unplaced(
                out_dir.clone(),
                None,
                format!("cannot create the directory: {e}"),
            )
        })?;
        // All or nothing, and only the files whose content changed.
        let io = |message: String| Error::unplaced(out_dir.clone(), None, message);
        let mut files = OutputFiles::default();
        let mut written = Vec::new();
        for (path, text) in outputs {
            if std::fs::read(&path).is_ok_and(|old| old == text.as_bytes()) {
                continue;
            }
            files.write_text(&path, &text).map_err(io)?;
            written.push(path);
        }
        files.commit().map_err(io)?;
        Ok(Report { scenes, written })
    }
}

fn index_source(scenes: &[Generated], index: &Index) -> Result<String, String> {
    let path = |s: &str| -> Result<syn::Path, String> {
        syn::parse_str(s).map_err(|e| format!("`{s}` is not a path: {e}"))
    };
    let wrapper = path(&index.wrapper)?;
    let trait_path = path(&index.trait_path)?;
    let mods = scenes.iter().map(|s| {
        let m = quote::format_ident!("{}", s.name);
        let file = format!("{}.rs", s.name);
        let doc = format!("Generated equations of scene `{}`.", s.name);
        quote! {
            #[doc = #doc]
            pub mod #m { include!(#file); }
        }
    });
    let names = scenes.iter().map(|s| s.name.as_str());
    let arms = scenes.iter().map(|s| {
        let m = quote::format_ident!("{}", s.name);
        let st = quote::format_ident!("{}", struct_name(&s.name));
        let name = s.name.as_str();
        quote! {
            #name => Some(#wrapper::<_, { #m::NQ }, { #m::NC }, { #m::NU }>(#m::#st::default())),
        }
    });
    let tokens = quote! {
        #(#mods)*

        /// Names of every generated scene.
        pub const SCENES: &[&str] = &[#(#names),*];

        /// The default model of a scene, by name.
        #[allow(clippy::default_constructed_unit_structs)]
        pub fn model(name: &str) -> Option<Box<dyn #trait_path>> {
            match name {
                #(#arms)*
                _ => None,
            }
        }
    };
    let file: syn::File = syn::parse2(tokens).map_err(|e| e.to_string())?;
    Ok(format!(
        "// @generated by flexdyn-codegen: index of the generated scenes.\n\n{}",
        prettyplease::unparse(&file)
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pendulum(dir: &Path) -> PathBuf {
        let path = dir.join("p.toml");
        std::fs::write(
            &path,
            "name = \"p\"\n[parameters]\nl = { value = 0.5 }\n\
             [[coordinates]]\nname = \"a\"\nrange = [-3.0, 3.0]\n\
             [[components]]\nname = \"bob\"\ntype = \"point_mass\"\nmass = 2\n\
             position = [\"l*sin(a)\", 0, \"-l*cos(a)\"]\n",
        )
        .unwrap();
        path
    }

    fn build(dir: &Path, scene: &str, function: &str, index: usize) -> Result<Report, Error> {
        Builder::new()
            .scene(pendulum(dir))
            .out_dir(dir.join("out"))
            .perturb_coefficient(scene, function, index, 1e-6)
            .generate()
    }

    #[test]
    fn a_perturbed_coefficient_changes_only_its_function_and_is_announced() {
        let dir = tempfile::tempdir().unwrap();
        let exact = generate_scene(&pendulum(dir.path())).unwrap().source;
        let report = build(dir.path(), "p", "bias", 0).unwrap();
        let perturbed = &report.scenes[0].source;
        assert!(perturbed.contains("TEST ONLY: coefficient 0 of `bias`"));
        let body = |s: &str, f: &str| {
            let start = s.find(&format!("fn {f}(")).unwrap();
            s[start..start + s[start..].find("\n    }\n").unwrap()].to_owned()
        };
        assert_ne!(body(perturbed, "bias"), body(&exact, "bias"));
        for f in ["mass_matrix", "dynamics_terms", "kinetic_energy"] {
            assert_eq!(body(perturbed, f), body(&exact, f), "{f} changed");
        }
    }

    #[test]
    fn a_perturbation_that_finds_nothing_is_an_error() {
        let dir = tempfile::tempdir().unwrap();
        for (scene, function, index, what) in [
            (
                "p",
                "bias",
                10_000,
                "cannot perturb coefficient 10000 of `bias`",
            ),
            ("p", "no_such_function", 0, "of `no_such_function`"),
            (
                "q",
                "bias",
                0,
                "cannot perturb scene `q`: it is not generated",
            ),
        ] {
            let e = build(dir.path(), scene, function, index).unwrap_err();
            assert!(e.to_string().contains(what), "{e}");
        }
        assert!(!dir.path().join("out").exists(), "nothing is written");
    }
}
