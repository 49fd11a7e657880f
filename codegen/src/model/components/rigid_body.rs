//! `rigid_body`: a rigid body of mass `m` turning with `frame`, centre of
//! mass at `position` (the frame's origin by default), inertia tensor about
//! its centre in frame axes: `T = (m |v|^2 + w . I w) / 2`, `V = -m g . r`.

use toml::Spanned;

use super::{required, Energies, Kind};
use crate::error::Error;
use crate::expr::Id;
use crate::geometry::{Frame, Point};
use crate::load::scene::{ComponentDef, SScalar};
use crate::model::context::Context;

pub(super) const KIND: Kind = Kind {
    name: "rigid_body",
    fields: &["mass", "position", "frame", "inertia"],
    adds_coordinates: false,
    read,
};

struct RigidBody {
    mass: SScalar,
    frame: Spanned<String>,
    position: Option<Spanned<Vec<SScalar>>>,
    inertia: Spanned<Vec<Vec<SScalar>>>,
}

fn read(cx: &Context, c: &ComponentDef, _: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    Ok(Box::new(RigidBody {
        mass: required(cx, c, &c.mass, ctx, "mass")?.clone(),
        frame: required(cx, c, &c.frame, ctx, "frame")?.clone(),
        position: c.position.clone(),
        inertia: required(cx, c, &c.inertia, ctx, "inertia")?.clone(),
    }))
}

impl Energies for RigidBody {
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<[Id; 3], Error> {
        let zero = cx.graph.constant(0.0);
        let m = cx.positive(&self.mass, ctx, "mass", true)?;
        let frame = cx.lookup_frame(&self.frame, ctx)?;
        let com = centre_of_mass(cx, &self.frame, &frame, self.position.as_ref(), ctx)?;
        let inertia = inertia(cx, &self.inertia, ctx)?;
        let (kinetic, potential) = body_energies(cx, m, &com, &frame, &inertia);
        Ok([kinetic, potential, zero])
    }
}

/// The centre of mass at `position` in the body's frame `frame_name`
/// (`frame`), or at the frame's origin.
pub(super) fn centre_of_mass(
    cx: &mut Context,
    frame_name: &Spanned<String>,
    frame: &Frame,
    position: Option<&Spanned<Vec<SScalar>>>,
    ctx: &str,
) -> Result<Point, Error> {
    match position {
        Some(p) => cx.point(Some(frame_name), p, ctx),
        None => Ok(Point {
            position: frame.origin,
            velocity: frame.velocity,
        }),
    }
}

/// Kinetic energy `(m v.v + w.I w) / 2` and gravity potential of a rigid
/// body of mass `m` with centre of mass `com`, turning with `frame`,
/// inertia about its centre in frame axes.
pub(super) fn body_energies(
    cx: &mut Context,
    m: Id,
    com: &Point,
    frame: &Frame,
    inertia: &[[Id; 3]; 3],
) -> (Id, Id) {
    let v2 = cx.graph.dot(com.velocity, com.velocity);
    let w = frame.omega;
    let iw = cx.graph.rotate(inertia, w);
    let wiw = cx.graph.dot(w, iw);
    let mv2 = cx.graph.mul(m, v2);
    let total = cx.graph.add(mv2, wiw);
    let kinetic = cx.graph.scale(total, 0.5);
    (kinetic, cx.gravity_potential(m, com.position))
}

/// The inertia tensor: 3x3, parameter-only, symmetric, positive definite.
fn inertia(
    cx: &mut Context,
    rows: &Spanned<Vec<Vec<SScalar>>>,
    ctx: &str,
) -> Result<[[Id; 3]; 3], Error> {
    let at = rows.span().start;
    if rows.get_ref().len() != 3 || rows.get_ref().iter().any(|r| r.len() != 3) {
        return Err(cx.err(at, Some(ctx), "inertia must be a 3x3 array"));
    }
    let mut ids = [[cx.graph.constant(0.0); 3]; 3];
    let mut val = [[0.0; 3]; 3];
    for (i, row) in rows.get_ref().iter().enumerate() {
        for (j, s) in row.iter().enumerate() {
            ids[i][j] = cx.scalar(s, Some(ctx), false)?;
            val[i][j] = cx.nominal_value(ids[i][j], s.span().start, ctx, "inertia")?;
        }
    }
    let scale = val.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    let asymmetric = [(0, 1), (0, 2), (1, 2)]
        .iter()
        .any(|&(i, j)| (val[i][j] - val[j][i]).abs() > 1e-12 * scale.max(1e-300));
    if asymmetric {
        return Err(cx.err(at, Some(ctx), "inertia tensor is not symmetric"));
    }
    if !positive_definite_3x3(&val) {
        return Err(cx.err(at, Some(ctx), "inertia tensor is not positive definite"));
    }
    Ok(ids)
}

/// Cholesky test for a symmetric 3x3 matrix.
fn positive_definite_3x3(a: &[[f64; 3]; 3]) -> bool {
    let mut l = [[0.0f64; 3]; 3];
    for i in 0..3 {
        for j in 0..=i {
            let s: f64 = a[i][j] - (0..j).map(|k| l[i][k] * l[j][k]).sum::<f64>();
            if i == j {
                if s.is_nan() || s <= 0.0 {
                    return false;
                }
                l[i][i] = s.sqrt();
            } else {
                l[i][j] = s / l[j][j];
            }
        }
    }
    true
}
