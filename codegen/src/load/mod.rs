//! Stage 1, load: a scene file's text to a typed scene.
//!
//! The TOML is read with serde into position-carrying structures
//! ([`scene`]); a derived scene (one with a top-level `base`) has its base
//! file read from the same directory, so the stages after this one see one
//! full scene and, for a derived scene, the reductions to apply to it. The
//! expression grammar ([`parse`]) is used by the next stage, which turns the
//! expressions into graph nodes.

pub mod parse;
pub mod scene;

use std::path::Path;

use toml::Spanned;

use crate::error::{Error, Source};
use crate::files::read_limited;
use parse::RESERVED;
use scene::{parse_scene_file, DerivedSceneDef, SceneDef, SceneFile, MAX_SCENE_BYTES};

/// A scene file read and resolved.
#[derive(Debug, Clone)]
pub struct LoadedScene {
    /// The file of the full scene (the base of a derived scene).
    pub source: Source,
    /// The full scene.
    pub def: SceneDef,
    /// A derived scene's own file and reductions.
    pub derived: Option<(Source, DerivedSceneDef)>,
}

/// Read a scene file.
pub fn load(path: &Path) -> Result<LoadedScene, Error> {
    let text = read_limited(path, MAX_SCENE_BYTES as u64, "scene file")
        .map_err(|e| Error::unplaced(path.to_path_buf(), None, e))?;
    resolve(Source::new(path, text))
}

/// Parse a scene file's text; a derived scene loads its base from the same
/// directory. Scene names are checked here: they name Rust modules.
pub fn resolve(source: Source) -> Result<LoadedScene, Error> {
    let def = match parse_scene_file(&source)? {
        SceneFile::Full(def) => def,
        SceneFile::Derived(def) => return resolve_derived(source, def),
    };
    check_scene_name(&source, &def.name)?;
    Ok(LoadedScene {
        source,
        def,
        derived: None,
    })
}

/// A derived scene: its base must be a full scene file in the same
/// directory.
fn resolve_derived(source: Source, def: DerivedSceneDef) -> Result<LoadedScene, Error> {
    check_scene_name(&source, &def.name)?;
    let base = def.base.get_ref();
    let plain = Path::new(base)
        .file_name()
        .is_some_and(|f| f == std::ffi::OsStr::new(base))
        && base.ends_with(".toml");
    if !plain {
        return Err(source.error_at(
            def.base.span().start,
            None,
            format!(
                "base `{base}` must be the file name of a scene (`*.toml`) in the \
                 same directory"
            ),
        ));
    }
    let path = source.path().with_file_name(base);
    let text = read_limited(&path, MAX_SCENE_BYTES as u64, "base scene").map_err(|e| {
        source.error_at(
            def.base.span().start,
            None,
            format!("{}: {e}", path.display()),
        )
    })?;
    let base_source = Source::new(&path, text);
    let SceneFile::Full(base_def) = parse_scene_file(&base_source)? else {
        return Err(source.error_at(
            def.base.span().start,
            None,
            format!("base `{base}` is itself a derived scene; derive from a full scene"),
        ));
    };
    check_scene_name(&base_source, &base_def.name)?;
    Ok(LoadedScene {
        source: base_source,
        def: base_def,
        derived: Some((source, def)),
    })
}

/// A scene name names a Rust module: an identifier in lower case.
fn check_scene_name(source: &Source, name: &Spanned<String>) -> Result<(), Error> {
    check_ident(source, name, "scene name")?;
    check_lower_case(source, name)
}

/// Whether `name` is a valid identifier for scene items.
pub(crate) fn check_ident(
    source: &Source,
    name: &Spanned<String>,
    what: &str,
) -> Result<(), Error> {
    let s = name.get_ref();
    let ok = s.len() <= 64
        && s.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
        && s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    if !ok {
        return Err(source.error_at(
            name.span().start,
            None,
            format!(
                "{what} `{s}` is not a valid name (a letter, then letters, digits or `_`, at most 64)"
            ),
        ));
    }
    if RESERVED.contains(&s.as_str()) || RUST_KEYWORDS.contains(&s.as_str()) {
        return Err(source.error_at(
            name.span().start,
            None,
            format!("{what} `{s}` is a reserved word"),
        ));
    }
    Ok(())
}

/// Scene names name Rust modules: lower case.
fn check_lower_case(source: &Source, name: &Spanned<String>) -> Result<(), Error> {
    if name.get_ref().chars().any(|c| c.is_ascii_uppercase()) {
        return Err(source.error_at(
            name.span().start,
            None,
            "scene name must be lower case (it names a Rust module)",
        ));
    }
    Ok(())
}

pub(crate) const RUST_KEYWORDS: &[&str] = &[
    "as", "async", "await", "break", "const", "continue", "crate", "dyn", "else", "enum", "extern",
    "false", "fn", "for", "gen", "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut",
    "pub", "ref", "return", "self", "Self", "static", "struct", "super", "trait", "true", "type",
    "unsafe", "use", "where", "while", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "try", "typeof", "unsized", "virtual", "yield", "union",
];
