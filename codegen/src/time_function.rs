//! Functions of time written in the scene's expression grammar, for inputs
//! and prescribed motions given on the command line (`--input tau=2*sin(w*t)`).
//!
//! The text is parsed by the scene parser ([`crate::load::parse`]) with the
//! scene's parameters bound to their nominal values and `t` free; a
//! coordinate, a velocity or an unknown name is an error located in the text.
//! The first and second time derivatives are built symbolically on the
//! expression graph (`d/dt` by the chain rule, [`crate::expr::diff`]), so
//! `eval` gives `f(t)`, `f'(t)`, `f''(t)` exactly, without finite differences.

use std::path::PathBuf;

use crate::error::Error;
use crate::expr::{Graph, Id, Symbol};
use crate::load::parse::{parse_expr, Binding, Scope};
use crate::model::Model;

/// `f(t)` with its first two time derivatives, from an expression text.
#[derive(Debug, Clone)]
pub struct TimeFunction {
    text: String,
    graph: Graph,
    /// `f`, `df/dt`, `d2f/dt2`.
    roots: [Id; 3],
}

impl TimeFunction {
    /// Parse `text` in the scope of `model`: `t`, `pi`, the functions of the
    /// grammar and the scene's parameters (at their nominal values).
    pub fn parse(model: &Model, text: &str) -> Result<TimeFunction, Error> {
        let scope = Scope {
            coordinates: model.coordinates.iter().map(|c| c.name.clone()).collect(),
            parameters: model
                .parameters
                .iter()
                .map(|(name, &value)| (name.clone(), Binding::Value(value)))
                .collect(),
            allow_velocity: true,
            points: Default::default(),
        };
        let mut graph = Graph::new();
        let f =
            parse_expr(&mut graph, text, &scope).map_err(|e| located(text, e.offset, e.message))?;
        // Coordinates and velocities are parsed (for a better message than
        // "undefined symbol"), then refused.
        if let Some(s) = graph
            .symbols(&[f])
            .into_iter()
            .find(|s| matches!(s, Symbol::Q(_) | Symbol::Qd(_)))
        {
            let (Symbol::Q(i) | Symbol::Qd(i)) = s else {
                unreachable!("filtered above")
            };
            let name = &scope.coordinates[i as usize];
            let what = if matches!(s, Symbol::Q(_)) {
                format!("the coordinate `{name}`")
            } else {
                format!("the velocity of `{name}`")
            };
            return Err(located(
                text,
                word_offset(text, name),
                format!(
                    "a function of time may use only `t` and the scene's parameters, not {what}"
                ),
            ));
        }
        let df = graph.diff(f, Symbol::Time);
        let ddf = graph.diff(df, Symbol::Time);
        Ok(TimeFunction {
            text: text.to_owned(),
            graph,
            roots: [f, df, ddf],
        })
    }

    /// The expression as written.
    pub fn text(&self) -> &str {
        &self.text
    }

    /// Value, first and second time derivative at `t` (non-finite where the
    /// expression is, e.g. `sqrt(t - 1)` before `t = 1`).
    pub fn eval(&self, t: f64) -> [f64; 3] {
        let v = self.graph.eval(&self.roots, &|s| match s {
            Symbol::Time => t,
            // `parse` refuses every other symbol: parameters are folded.
            _ => f64::NAN,
        });
        [v[0], v[1], v[2]]
    }
}

/// An error at a byte offset of an expression given outside a scene file:
/// the "file" is the expression text itself, on line 1.
fn located(text: &str, offset: usize, message: String) -> Error {
    let column = text
        .get(..offset.min(text.len()))
        .map_or(offset, |s| s.chars().count())
        + 1;
    Error {
        file: PathBuf::from(format!("`{text}`")),
        line: 1,
        column,
        context: None,
        message,
    }
}

/// Byte offset of the first occurrence of `name` as a whole word (or of
/// `q[`/`qd[` when it is written by index), 0 when not found.
fn word_offset(text: &str, name: &str) -> usize {
    let is_ident = |c: char| c.is_alphanumeric() || c == '_';
    let whole = |at: usize, len: usize| {
        !text[..at].ends_with(is_ident) && !text[at + len..].starts_with(is_ident)
    };
    text.match_indices(name)
        .find(|&(at, _)| whole(at, name.len()))
        .or_else(|| {
            text.match_indices("q")
                .find(|&(at, _)| whole(at, 1) || text[at..].starts_with("qd["))
        })
        .map_or(0, |(at, _)| at)
}

#[cfg(test)]
mod tests {
    use std::path::Path;

    use super::*;
    use crate::error::Source;

    const SCENE: &str = r#"
name = "oscillator"
[parameters]
w = 3.0
a = { value = 0.5, runtime = true }
[[coordinates]]
name = "x"
[[components]]
name = "mass"
type = "point_mass"
mass = 1.0
position = ["x", 0, 0]
"#;

    fn model() -> Model {
        Model::from_source(&Source::new(Path::new("osc.toml"), SCENE.to_owned())).unwrap()
    }

    #[test]
    fn derivatives_match_closed_forms() {
        let f = TimeFunction::parse(&model(), "a*sin(w*t) + t*t*t").unwrap();
        for t in [0.0, 0.3, 1.7] {
            let [v, d, dd] = f.eval(t);
            let (a, w) = (0.5, 3.0);
            assert!((v - (a * (w * t).sin() + t * t * t)).abs() < 1e-14);
            assert!((d - (a * w * (w * t).cos() + 3.0 * t * t)).abs() < 1e-13);
            assert!((dd - (-a * w * w * (w * t).sin() + 6.0 * t)).abs() < 1e-13);
        }
        let g = TimeFunction::parse(&model(), "exp(-t)*cos(2*t)").unwrap();
        let t: f64 = 0.8;
        let [_, d, dd] = g.eval(t);
        let (e, c, s) = ((-t).exp(), (2.0 * t).cos(), (2.0 * t).sin());
        assert!((d - (-e * c - 2.0 * e * s)).abs() < 1e-14);
        assert!((dd - (-3.0 * e * c + 4.0 * e * s)).abs() < 1e-14);
        assert_eq!(
            TimeFunction::parse(&model(), "2.5").unwrap().eval(1.0),
            [2.5, 0.0, 0.0]
        );
    }

    /// The spin-up profile written with `step` (C3 at the switch, so the
    /// dropped derivative of `step` loses nothing) against its closed form.
    #[test]
    fn spin_up_profile_with_step_has_the_closed_form_derivatives() {
        let (ts, ws) = (15.0, 6.0);
        let f = TimeFunction::parse(
            &model(),
            "step(15 - t)*(6/15)*(t*t/2 + powi(15/(2*pi), 2)*(cos(2*pi*t/15) - 1)) + step(t - 15)*6*(t - 7.5)",
        )
        .unwrap();
        let k = ts / (2.0 * std::f64::consts::PI);
        for t in [0.0, 3.0, 14.9, 15.0, 15.1, 20.0] {
            let want = if t < ts {
                let (s, c) = (t / k).sin_cos();
                [
                    ws / ts * (t * t / 2.0 + k * k * (c - 1.0)),
                    ws / ts * (t - k * s),
                    ws / ts * (1.0 - c),
                ]
            } else {
                [ws * (t - ts / 2.0), ws, 0.0]
            };
            let got = f.eval(t);
            for (g, w) in got.iter().zip(want) {
                assert!(
                    (g - w).abs() < 1e-13 * (1.0 + w.abs()),
                    "t = {t}: {got:?} vs {want:?}"
                );
            }
        }
    }

    #[test]
    fn coordinates_velocities_and_unknown_names_are_located_errors() {
        let m = model();
        let e = TimeFunction::parse(&m, "sin(t) + x").unwrap_err();
        assert_eq!((e.line, e.column), (1, 10), "{e}");
        assert!(e.to_string().contains("`sin(t) + x`"), "{e}");
        assert!(e.message.contains("coordinate `x`"), "{e}");
        let e = TimeFunction::parse(&m, "t*dot(x)").unwrap_err();
        assert!(e.message.contains("velocity of `x`"), "{e}");
        let e = TimeFunction::parse(&m, "2*q[0]").unwrap_err();
        assert_eq!(e.column, 3, "{e}");
        let e = TimeFunction::parse(&m, "t + omega").unwrap_err();
        assert!(e.message.contains("undefined symbol `omega`"), "{e}");
        assert_eq!(e.column, 5, "{e}");
        assert!(TimeFunction::parse(&m, "sin(t").is_err());
    }
}
