//! Helpers shared by the integration tests: scene discovery and seeded random states.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use flexdyn::codegen::Model;
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// Every scene file shipped in `scenes/`, with its parsed model.
pub fn scenes() -> Vec<(PathBuf, Model)> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("scenes/ exists")
        .map(|e| e.expect("readable entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    files.sort();
    files
        .into_iter()
        .map(|f| {
            let m = Model::load(&f).unwrap_or_else(|e| panic!("{e}"));
            (f, m)
        })
        .collect()
}

/// A seeded generator, so that failures reproduce.
pub fn rng(seed: u64) -> StdRng {
    StdRng::seed_from_u64(seed)
}

/// A random state within the scene's declared ranges (defaults: +-pi, +-2).
pub fn random_state(model: &Model, rng: &mut StdRng) -> (Vec<f64>, Vec<f64>, f64) {
    let q = model
        .coordinates
        .iter()
        .map(|c| {
            let [a, b] = c.range.unwrap_or([-3.0, 3.0]);
            rng.gen_range(a..b)
        })
        .collect();
    let qd = model
        .coordinates
        .iter()
        .map(|c| {
            let [a, b] = c.velocity_range.unwrap_or([-2.0, 2.0]);
            rng.gen_range(a..b)
        })
        .collect();
    (q, qd, rng.gen_range(0.0..5.0))
}

/// `max |a - b|` over two slices.
pub fn max_diff(a: &[f64], b: &[f64]) -> f64 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

/// `max |a|` over a slice (at least `floor`).
pub fn max_abs(a: &[f64], floor: f64) -> f64 {
    a.iter().map(|x| x.abs()).fold(floor, f64::max)
}
