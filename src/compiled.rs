//! The model that answers for a scene file, for every command that takes
//! one: the compiled-in module of a scene of that name when the file still
//! describes it (same terms, bitwise, at a sample state), else the file
//! generated in memory and interpreted ([`crate::interpreted`]); bitwise
//! the same numbers either way.

use std::path::Path;

use crate::dynamic::{matrix, DynModel};

/// The scenes a binary has compiled in: the index modules that
/// `flexdyn_codegen::Builder::index` writes.
#[derive(Debug, Clone, Copy)]
pub struct Compiled {
    /// Names of the compiled scenes.
    pub scenes: &'static [&'static str],
    /// The default model of a compiled scene, by name.
    pub model: fn(&str) -> Option<Box<dyn DynModel>>,
    /// Names of the test-only perturbed builds.
    pub perturbed_scenes: &'static [&'static str],
    /// The default model of a perturbed build, by name.
    pub perturbed_model: fn(&str) -> Option<Box<dyn DynModel>>,
}

/// Which model answers for a scene file (see [`Compiled::choose`]).
pub enum Choice {
    /// The compiled-in module of the same terms.
    Compiled(Box<dyn DynModel>),
    /// The file, generated in memory and interpreted.
    Interpreted(crate::interpreted::InterpretedModel),
}

impl Compiled {
    /// The compiled-in model when the file describes it (same terms,
    /// bitwise, at a sample state; so an edited copy of a shipped scene is
    /// never answered by the stale compiled module), else the file
    /// interpreted. `interpret` forces the latter.
    pub fn choose(&self, scene: &Path, name: &str, interpret: bool) -> Result<Choice, String> {
        let interpreted = crate::interpreted::InterpretedModel::load(scene)?;
        match (self.model)(name).filter(|_| !interpret) {
            Some(c) if same_terms(c.as_ref(), &interpreted) => Ok(Choice::Compiled(c)),
            Some(_) => {
                eprintln!(
                    "note: {} differs from the compiled-in scene `{name}`: interpreting it",
                    scene.display()
                );
                Ok(Choice::Interpreted(interpreted))
            }
            None => Ok(Choice::Interpreted(interpreted)),
        }
    }

    /// The model of a scene file, chosen as [`Compiled::choose`] says.
    pub fn load(
        &self,
        scene: &Path,
        name: &str,
        interpret: bool,
    ) -> Result<Box<dyn DynModel>, String> {
        Ok(match self.choose(scene, name, interpret)? {
            Choice::Compiled(c) => c,
            Choice::Interpreted(i) => Box::new(i),
        })
    }
}

/// Whether two models give the same terms at a sample state.
fn same_terms(a: &dyn DynModel, b: &dyn DynModel) -> bool {
    if a.coordinates() != b.coordinates()
        || a.actuators() != b.actuators()
        || a.nc() != b.nc()
        || a.markers() != b.markers()
    {
        return false;
    }
    let q: Vec<f64> = (0..a.nq()).map(|i| 0.3 + 0.17 * i as f64).collect();
    let qd: Vec<f64> = (0..a.nq()).map(|i| -0.4 + 0.23 * i as f64).collect();
    let qdd: Vec<f64> = (0..a.nq()).map(|i| 0.8 - 0.31 * i as f64).collect();
    let t = 0.37;
    let (nq, nc, nu) = (a.nq(), a.nc(), a.nu());
    let same = |n: usize, f: &dyn Fn(&dyn DynModel, &mut [f64])| {
        matrix(n, 1, |o| f(a, o)) == matrix(n, 1, |o| f(b, o))
    };
    same(nq * nq, &|m, o| m.mass_matrix(&q, t, o))
        && same(nq, &|m, o| m.bias(&q, &qd, t, o))
        && same(nq, &|m, o| m.inverse_dynamics(&q, &qd, &qdd, t, o))
        && same(nc, &|m, o| m.constraints(&q, t, o))
        && same(nq * nu, &|m, o| m.actuator_map(o))
        && a.potential_energy(&q, t) == b.potential_energy(&q, t)
        && (0..a.markers().len()).all(|k| {
            let pose = |m: &dyn DynModel, o: &mut [f64]| {
                let (position, rotation) = o.split_at_mut(3);
                m.marker_pose(k, &q, t, position, rotation);
            };
            same(12, &pose)
        })
}

/// The generic scenes of `scenes/`, compiled into this crate.
pub const COMPILED_SCENES: Compiled = Compiled {
    scenes: crate::scenes::SCENES,
    model: crate::scenes::model,
    perturbed_scenes: crate::perturbed_scenes::SCENES,
    perturbed_model: crate::perturbed_scenes::model,
};
