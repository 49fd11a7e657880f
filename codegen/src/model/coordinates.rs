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
            out.push(Coordinate {
                name: c.name.get_ref().clone(),
                range: range(&c.range)?,
                velocity_range: range(&c.velocity_range)?,
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
