//! `rigid_body`: a rigid body of mass `m` turning with `frame`, centre of
//! mass at `position` (the frame's origin by default), inertia tensor `I0`
//! about its centre: `T = (m |v|^2 + w . I w) / 2`, `V = -m g . r`, with
//! `I = R I0 R^T` in frame axes, `R = Rz(yaw) Ry(pitch) Rx(roll)` from
//! `inertia_rpy` (the URDF convention; identity by default). The mass may be
//! zero and the tensor singular (massless and point-like bodies): the mass
//! must be non-negative and `I0` symmetric positive semi-definite, its
//! principal moments obeying the triangle inequality, unless
//! `allow_unphysical_inertia = true` (kept for tensors published that way,
//! which URDF files have: positive semi-definite still required). The
//! tolerances are relative to the body's scale
//! ([`crate::inertia::inertia_problem`]).

use toml::Spanned;

use super::{required, Energies, Kind, Terms};
use crate::error::Error;
use crate::expr::Id;
use crate::geometry::{Frame, Point};
use crate::inertia::{inertia_problem, parallel_axis_scale, Unphysical};
use crate::load::scene::{ComponentDef, InertiaEntry, SScalar, Scalar};
use crate::model::context::Context;
use crate::model::{Attachment, Body};

pub(super) const KIND: Kind = Kind {
    name: "rigid_body",
    fields: &[
        "mass",
        "position",
        "frame",
        "inertia",
        "inertia_rpy",
        "allow_unphysical_inertia",
    ],
    adds_coordinates: false,
    read,
};

struct RigidBody {
    mass: SScalar,
    frame: Spanned<String>,
    position: Option<Spanned<Vec<SScalar>>>,
    inertia: Spanned<Vec<Spanned<InertiaEntry>>>,
    inertia_rpy: Option<Spanned<Vec<SScalar>>>,
    allow_unphysical: bool,
}

fn read(cx: &Context, c: &ComponentDef, _: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    Ok(Box::new(RigidBody {
        mass: required(cx, c, &c.mass, ctx, "mass")?.clone(),
        frame: required(cx, c, &c.frame, ctx, "frame")?.clone(),
        position: c.position.clone(),
        inertia: required(cx, c, &c.inertia, ctx, "inertia")?.clone(),
        inertia_rpy: c.inertia_rpy.clone(),
        allow_unphysical: c
            .allow_unphysical_inertia
            .as_ref()
            .is_some_and(|b| *b.get_ref()),
    }))
}

impl Energies for RigidBody {
    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error> {
        let m = cx.positive(&self.mass, ctx, "mass", false)?;
        let frame = cx.lookup_frame(&self.frame, ctx)?;
        let com = centre_of_mass(cx, &self.frame, &frame, self.position.as_ref(), ctx)?;
        let floor = body_scale(cx, m, &com);
        let inertia = inertia(cx, &self.inertia, floor, self.allow_unphysical, ctx)?;
        let inertia = match &self.inertia_rpy {
            Some(rpy) => rotated(cx, &inertia, rpy, ctx)?,
            None => inertia,
        };
        Ok(body_terms(cx, m, &com, frame.omega, Some(inertia)))
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
            node: frame.node,
            local: [cx.graph.constant(0.0); 3],
        }),
    }
}

/// The terms of a body of mass `m` with centre of mass `com`, turning at
/// `omega` (frame axes), inertia about its centre in the same axes (`None`
/// for a point mass): kinetic energy `(m v.v + w.I w) / 2`, gravity
/// potential, no dissipation, and the body's form of `T`.
pub(super) fn body_terms(
    cx: &mut Context,
    m: Id,
    com: &Point,
    omega: [Id; 3],
    inertia: Option<[[Id; 3]; 3]>,
) -> Terms {
    let v2 = cx.graph.dot(com.velocity, com.velocity);
    let mut total = cx.graph.mul(m, v2);
    if let Some(inertia) = &inertia {
        let iw = cx.graph.rotate(inertia, omega);
        let wiw = cx.graph.dot(omega, iw);
        total = cx.graph.add(total, wiw);
    }
    let kinetic = cx.graph.scale(total, 0.5);
    let potential = cx.gravity_potential(m, com.position);
    let zero = cx.graph.constant(0.0);
    Terms {
        energies: [kinetic, potential, zero],
        bodies: vec![Body {
            mass: m,
            velocity: com.velocity,
            omega,
            inertia,
            attached: com.node.map(|node| Attachment {
                node,
                centre: com.local,
            }),
        }],
        weight: Some(potential),
    }
}

/// The body's moment about its frame's origin from its mass, at nominal
/// values ([`parallel_axis_scale`]; zero where the centre moves in the
/// frame).
fn body_scale(cx: &Context, m: Id, com: &Point) -> f64 {
    let value = |id: Id| cx.nominal_value(id, 0, "", "").ok();
    let centre = com.local.map(value);
    match (value(m), centre) {
        (Some(m), [Some(x), Some(y), Some(z)]) => {
            parallel_axis_scale(m, &nalgebra::Vector3::new(x, y, z))
        }
        _ => 0.0,
    }
}

/// The inertia tensor, full (three rows) or diagonal (three values):
/// parameter-only, symmetric, positive semi-definite and, unless
/// `allow_unphysical`, a tensor some mass distribution has; `floor` is the
/// body's scale for the tolerances.
fn inertia(
    cx: &mut Context,
    entries: &Spanned<Vec<Spanned<InertiaEntry>>>,
    floor: f64,
    allow_unphysical: bool,
    ctx: &str,
) -> Result<[[Id; 3]; 3], Error> {
    let at = entries.span().start;
    let shape = "inertia must be a 3x3 array (three rows) or the diagonal `[ixx, iyy, izz]`";
    let zero = Spanned::new(at..at, Scalar::Number(0.0));
    let mut cells: [[&SScalar; 3]; 3] = [[&zero; 3]; 3];
    let items = entries.get_ref();
    if items.len() != 3 {
        return Err(cx.err(at, Some(ctx), shape));
    }
    let diagonal: Vec<SScalar>;
    if items
        .iter()
        .all(|e| matches!(e.get_ref(), InertiaEntry::Diagonal(_)))
    {
        diagonal = items
            .iter()
            .map(|e| match e.get_ref() {
                InertiaEntry::Diagonal(v) => Spanned::new(e.span(), v.clone()),
                InertiaEntry::Row(_) => unreachable!("checked above"),
            })
            .collect();
        for (k, d) in diagonal.iter().enumerate() {
            cells[k][k] = d;
        }
    } else {
        for (i, e) in items.iter().enumerate() {
            match e.get_ref() {
                InertiaEntry::Row(r) if r.len() == 3 => {
                    for (j, s) in r.iter().enumerate() {
                        cells[i][j] = s;
                    }
                }
                _ => return Err(cx.err(e.span().start, Some(ctx), shape)),
            }
        }
    }
    let mut ids = [[cx.graph.constant(0.0); 3]; 3];
    let mut val = [[0.0; 3]; 3];
    for i in 0..3 {
        for j in 0..3 {
            let s = cells[i][j];
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
    match inertia_problem(&nalgebra::Matrix3::from_fn(|i, j| val[i][j]), floor) {
        None => {}
        Some(Unphysical::Triangle { .. }) if allow_unphysical => {}
        Some(problem @ Unphysical::Triangle { .. }) => {
            return Err(cx.err(
                at,
                Some(ctx),
                format!(
                    "{} (`allow_unphysical_inertia = true` keeps such a tensor)",
                    problem.message()
                ),
            ))
        }
        Some(problem) => return Err(cx.err(at, Some(ctx), problem.message())),
    }
    Ok(ids)
}

/// `R I R^T` with `R = Rz(yaw) Ry(pitch) Rx(roll)` from `[roll, pitch, yaw]`
/// (parameter-only angles).
fn rotated(
    cx: &mut Context,
    inertia: &[[Id; 3]; 3],
    rpy: &Spanned<Vec<SScalar>>,
    ctx: &str,
) -> Result<[[Id; 3]; 3], Error> {
    let [roll, pitch, yaw] = rpy.get_ref().as_slice() else {
        return Err(cx.err(
            rpy.span().start,
            Some(ctx),
            "inertia_rpy must be `[roll, pitch, yaw]` (three angles, radians)",
        ));
    };
    let mut angle = |s: &SScalar| -> Result<Id, Error> {
        let id = cx.scalar(s, Some(ctx), false)?;
        cx.nominal_value(id, s.span().start, ctx, "inertia_rpy")?;
        Ok(id)
    };
    let (r, p, y) = (angle(roll)?, angle(pitch)?, angle(yaw)?);
    let g = &mut cx.graph;
    let rz = g.axis_rotation([0.0, 0.0, 1.0], y);
    let ry = g.axis_rotation([0.0, 1.0, 0.0], p);
    let rx = g.axis_rotation([1.0, 0.0, 0.0], r);
    let rzy = g.matmul(&rz, &ry);
    let rot = g.matmul(&rzy, &rx);
    let transpose: [[Id; 3]; 3] = std::array::from_fn(|i| std::array::from_fn(|j| rot[j][i]));
    let ri = g.matmul(&rot, inertia);
    Ok(g.matmul(&ri, &transpose))
}
