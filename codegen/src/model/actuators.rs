//! Actuators (a unit input's generalized force on one coordinate, times a
//! gain) and the optional outputs a scene asks for.

use super::context::Context;
use super::{Actuator, Coordinate, Outputs, Precision};
use crate::error::Error;
use crate::load::check_ident;
use crate::load::scene::SceneDef;

impl Context<'_> {
    /// The scene's actuators, each driving a declared coordinate.
    pub(super) fn actuators(
        &self,
        def: &SceneDef,
        coordinates: &[Coordinate],
    ) -> Result<Vec<Actuator>, Error> {
        let mut actuators = Vec::new();
        for a in &def.actuators {
            check_ident(self.source, &a.name, "actuator")?;
            let Some(coordinate) = coordinates
                .iter()
                .position(|c| c.name == *a.coordinate.get_ref())
            else {
                return Err(self.err(
                    a.coordinate.span().start,
                    Some(&format!("actuator `{}`", a.name.get_ref())),
                    format!("coordinate `{}` is not declared", a.coordinate.get_ref()),
                ));
            };
            let gain = a.gain.as_ref().map_or(1.0, |g| *g.get_ref());
            if !gain.is_finite() {
                let at = a.gain.as_ref().map_or(0, |g| g.span().start);
                return Err(self.err(at, None, "actuator gain is not finite"));
            }
            actuators.push(Actuator {
                name: a.name.get_ref().clone(),
                coordinate,
                gain,
            });
        }
        Ok(actuators)
    }

    /// The scene's `precision` (default `f64`).
    pub(super) fn precision(&self, def: &SceneDef) -> Result<Precision, Error> {
        match &def.precision {
            None => Ok(Precision::F64),
            Some(p) => match p.get_ref().as_str() {
                "f64" => Ok(Precision::F64),
                "f32" => Ok(Precision::F32),
                other => Err(self.err(
                    p.span().start,
                    None,
                    format!("unknown precision `{other}` (known: f64, f32)"),
                )),
            },
        }
    }

    /// The optional outputs named by the scene.
    pub(super) fn outputs(&self, def: &SceneDef) -> Result<Outputs, Error> {
        let mut outputs = Outputs::default();
        for o in &def.outputs {
            match o.get_ref().as_str() {
                "coriolis_matrix" => outputs.coriolis_matrix = true,
                "forces" => outputs.forces = true,
                "bias_jacobians" => outputs.bias_jacobians = true,
                other => {
                    return Err(self.err(
                        o.span().start,
                        None,
                        format!(
                        "unknown output `{other}` (known: coriolis_matrix, forces, bias_jacobians)"
                    ),
                    ))
                }
            }
        }
        Ok(outputs)
    }
}
