//! Actuators (a unit input's generalized force on one coordinate, times a
//! gain, and the rotor inertia reflected to it, `armature`: the kinetic
//! energy `armature qd^2 / 2`) and the optional outputs a scene asks for.

use super::context::Context;
use super::{Actuator, Component, Coordinate, Outputs, Precision};
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
            if actuators
                .iter()
                .any(|b: &Actuator| b.name == *a.name.get_ref())
            {
                return Err(self.err(
                    a.name.span().start,
                    Some(&format!("actuator `{}`", a.name.get_ref())),
                    "an actuator of this name is declared above (inputs are given by name)",
                ));
            }
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

    /// The rotor inertias of the actuators that declare `armature`, as
    /// components `<actuator>_armature` with `T = armature qd^2 / 2`
    /// (`armature` non-negative, parameter-only). Called after
    /// [`Context::actuators`], which checks names and coordinates.
    pub(super) fn armatures(
        &mut self,
        def: &SceneDef,
        actuators: &[Actuator],
    ) -> Result<Vec<Component>, Error> {
        let mut out = Vec::new();
        for (a, actuator) in def.actuators.iter().zip(actuators) {
            let Some(s) = &a.armature else { continue };
            let ctx = format!("actuator `{}`", actuator.name);
            let inertia = self.positive(s, &ctx, "armature", false)?;
            let rate = self.graph.qd(actuator.coordinate);
            let rate2 = self.graph.powi(rate, 2);
            let product = self.graph.mul(inertia, rate2);
            let zero = self.graph.constant(0.0);
            out.push(Component {
                name: format!("{}_armature", actuator.name),
                kind: "armature".to_owned(),
                kinetic: self.graph.scale(product, 0.5),
                potential: zero,
                dissipation: zero,
                bodies: Vec::new(),
                weight: None,
            });
        }
        Ok(out)
    }

    /// The optional outputs named by the scene.
    pub(super) fn outputs(&self, def: &SceneDef) -> Result<Outputs, Error> {
        let mut outputs = Outputs::default();
        for o in &def.outputs {
            match o.get_ref().as_str() {
                "coriolis_matrix" => outputs.coriolis_matrix = true,
                "forces" => outputs.forces = true,
                "bias_jacobians" => outputs.bias_jacobians = true,
                "dynamics_derivatives" => outputs.dynamics_derivatives = true,
                other => {
                    return Err(self.err(
                        o.span().start,
                        None,
                        format!(
                            "unknown output `{other}` (known: {})",
                            super::OUTPUTS.join(", ")
                        ),
                    ))
                }
            }
        }
        Ok(outputs)
    }
}
