//! Coordinates and parameters: the names expressions may use. Coordinates
//! are checked (names, ranges); parameters are folded to their values or,
//! when `runtime`, kept as fields of the generated model.

use toml::Spanned;

use super::context::Context;
use super::{Coordinate, RuntimeParameter};
use crate::error::Error;
use crate::load::check_ident;
use crate::load::parse::Binding;
use crate::load::scene::{ParameterDef, SceneDef};

impl Context<'_> {
    pub(super) fn coordinates(&mut self, def: &SceneDef) -> Result<Vec<Coordinate>, Error> {
        if def.coordinates.is_empty() {
            return Err(self.source.error("the scene declares no coordinates"));
        }
        let mut out: Vec<Coordinate> = Vec::new();
        for c in &def.coordinates {
            check_ident(self.source, &c.name, "coordinate")?;
            if out.iter().any(|o| o.name == *c.name.get_ref()) {
                return Err(self.err(
                    c.name.span().start,
                    None,
                    format!("coordinate `{}` is declared twice", c.name.get_ref()),
                ));
            }
            let range = |r: &Option<Spanned<[f64; 2]>>| -> Result<Option<[f64; 2]>, Error> {
                match r {
                    Some(r) => {
                        let [a, b] = *r.get_ref();
                        if !(a.is_finite() && b.is_finite() && a < b) {
                            return Err(self.err(
                                r.span().start,
                                None,
                                "a range must be two finite numbers, low < high",
                            ));
                        }
                        Ok(Some([a, b]))
                    }
                    None => Ok(None),
                }
            };
            let range_of_positions = range(&c.range)?;
            let velocity_range = range(&c.velocity_range)?;
            let initial = |v: &Option<Spanned<f64>>,
                           key: &str,
                           within: Option<[f64; 2]>|
             -> Result<f64, Error> {
                let Some(v) = v else { return Ok(0.0) };
                let x = *v.get_ref();
                let at = v.span().start;
                let ctx = format!("coordinate `{}`", c.name.get_ref());
                if !x.is_finite() {
                    return Err(self.err(at, Some(&ctx), format!("`{key}` is not finite ({x})")));
                }
                if let Some([lo, hi]) = within.filter(|[lo, hi]| !(*lo..=*hi).contains(&x)) {
                    return Err(self.err(
                        at,
                        Some(&ctx),
                        format!("`{key}` = {x} lies outside the declared range [{lo}, {hi}]"),
                    ));
                }
                Ok(x)
            };
            out.push(Coordinate {
                name: c.name.get_ref().clone(),
                initial: initial(&c.initial, "initial", range_of_positions)?,
                initial_velocity: initial(&c.initial_velocity, "initial_velocity", velocity_range)?,
                range: range_of_positions,
                velocity_range,
            });
        }
        self.scope.coordinates = out.iter().map(|c| c.name.clone()).collect();
        Ok(out)
    }

    pub(super) fn parameters(&mut self, def: &SceneDef) -> Result<Vec<RuntimeParameter>, Error> {
        let mut runtime = Vec::new();
        for (name, p) in &def.parameters {
            check_ident(self.source, name, "parameter")?;
            if self.scope.coordinates.contains(name.get_ref()) {
                return Err(self.err(
                    name.span().start,
                    None,
                    format!(
                        "parameter `{}` has the name of a coordinate",
                        name.get_ref()
                    ),
                ));
            }
            let (value, is_runtime) = match p.get_ref() {
                ParameterDef::Value(v) => (*v, false),
                ParameterDef::Table(t) => (t.value, t.runtime),
            };
            if !value.is_finite() {
                return Err(self.err(
                    p.span().start,
                    Some(&format!("parameter `{}`", name.get_ref())),
                    format!("value is not finite ({value})"),
                ));
            }
            let binding = if is_runtime {
                runtime.push(RuntimeParameter {
                    name: name.get_ref().clone(),
                    value,
                });
                self.nominal.push(value);
                Binding::Runtime(runtime.len() as u32 - 1)
            } else {
                Binding::Value(value)
            };
            self.scope
                .parameters
                .insert(name.get_ref().clone(), binding);
            self.parameter_values.insert(name.get_ref().clone(), value);
        }
        Ok(runtime)
    }
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use crate::error::Source;
    use crate::model::Model;

    fn load(coordinate: &str) -> Result<Model, crate::error::Error> {
        let text = format!(
            "name = \"s\"\n[[coordinates]]\nname = \"x\"\n{coordinate}\n\
             [[components]]\nname = \"m\"\ntype = \"point_mass\"\nmass = 1.0\n\
             position = [\"x\", 0, 0]\n"
        );
        Model::from_source(&Source::new(Path::new("s.toml"), text))
    }

    #[test]
    fn initial_state_keys_default_to_zero_and_are_checked() {
        let m = load("").unwrap();
        assert_eq!(
            (m.coordinates[0].initial, m.coordinates[0].initial_velocity),
            (0.0, 0.0)
        );
        let m = load("initial = 0.25\ninitial_velocity = -2.0").unwrap();
        assert_eq!(
            (m.coordinates[0].initial, m.coordinates[0].initial_velocity),
            (0.25, -2.0)
        );
        let e = load("range = [-1.0, 1.0]\ninitial = 1.5").unwrap_err();
        assert_eq!(e.line, 5, "{e}");
        assert!(
            e.to_string()
                .contains("coordinate `x`: `initial` = 1.5 lies outside"),
            "{e}"
        );
        let e = load("velocity_range = [-1.0, 1.0]\ninitial_velocity = -3.0").unwrap_err();
        assert!(e.message.contains("`initial_velocity` = -3"), "{e}");
        assert!(load("initial = nan").is_err());
    }
}
