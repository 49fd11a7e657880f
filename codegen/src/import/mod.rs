//! Importers: descriptions in other formats written as the text of a scene
//! file, which the pipeline then loads like any other (not a stage of it).
//! `urdf`: robots described in URDF.

mod urdf;

pub use urdf::{import_urdf, UrdfOptions};
