//! `flexible_link`: an elastic beam in the floating frame of reference.
//!
//! Its finite-element model ([`crate::fem`]) is built numerically when the
//! scene is read, before the frames: the kept modes' coordinates
//! `<name>_eta<j>` are appended to the declared ones, and frames may follow
//! the deformed centre line at a `station`. The energies use the modal
//! inertia invariants (see the [`crate::fem`] module docs for the formulas).

use nalgebra::DMatrix;
use toml::Spanned;

use super::{required, Energies, Kind, Terms};
use crate::error::Error;
use crate::expr::{Graph, Id};
use crate::fem::{
    Beam, BoundaryConditions, FeModel, Invariants, ModeSelection, Section, RY, RZ, UX,
};
use crate::geometry::Frame;
use crate::load::scene::{
    ComponentDef, EndStiffnessDef, FrameDef, MaterialDef, SScalar, Scalar, ScalarList, SectionDef,
};
use crate::model::context::Context;
use crate::model::{Coordinate, FlexibleLink};

/// Fields of a `flexible_link` component.
const FIELDS: &[&str] = &[
    "frame",
    "length",
    "material",
    "section",
    "elements",
    "modes",
    "max_frequency",
    "boundary",
    "end_stiffness",
    "damping_ratio",
    "geometric_stiffening",
];

/// Most finite elements of one flexible link.
pub const MAX_ELEMENTS: usize = 200;
/// Most modes of one flexible link.
pub const MAX_MODES: usize = 60;

pub(super) const KIND: Kind = Kind {
    name: "flexible_link",
    fields: FIELDS,
    adds_coordinates: true,
    read,
};

struct Link {
    name: String,
    kind_at: usize,
    name_at: usize,
    frame: Spanned<String>,
    length: SScalar,
    material: Spanned<MaterialDef>,
    section: Spanned<SectionDef>,
    boundary: Spanned<String>,
    elements: Option<SScalar>,
    modes: Option<SScalar>,
    max_frequency: Option<SScalar>,
    end_stiffness: Option<Spanned<EndStiffnessDef>>,
    damping_ratio: Option<Spanned<ScalarList>>,
    geometric_stiffening: Option<Spanned<bool>>,
    /// The finite-element data, once prepared.
    prepared: Option<FlexibleLink>,
}

fn read(cx: &Context, c: &ComponentDef, name: &str, ctx: &str) -> Result<Box<dyn Energies>, Error> {
    let kind_at = c.kind.span().start;
    Ok(Box::new(Link {
        name: name.to_owned(),
        kind_at,
        name_at: c.name.as_ref().map_or(kind_at, |n| n.span().start),
        frame: required(cx, c, &c.frame, ctx, "frame")?.clone(),
        length: required(cx, c, &c.length, ctx, "length")?.clone(),
        material: required(cx, c, &c.material, ctx, "material")?.clone(),
        section: required(cx, c, &c.section, ctx, "section")?.clone(),
        boundary: required(cx, c, &c.boundary, ctx, "boundary")?.clone(),
        elements: c.elements.clone(),
        modes: c.modes.clone(),
        max_frequency: c.max_frequency.clone(),
        end_stiffness: c.end_stiffness.clone(),
        damping_ratio: c.damping_ratio.clone(),
        geometric_stiffening: c.geometric_stiffening.clone(),
        prepared: None,
    }))
}

impl Energies for Link {
    fn prepare(
        &mut self,
        cx: &mut Context,
        coordinates: &mut Vec<Coordinate>,
        ctx: &str,
    ) -> Result<(), Error> {
        self.prepared = Some(self.build(cx, coordinates, ctx)?);
        Ok(())
    }

    fn flexible_link(&self) -> Option<&FlexibleLink> {
        self.prepared.as_ref()
    }

    fn energies(&self, cx: &mut Context, ctx: &str) -> Result<Terms, Error> {
        let link = self
            .prepared
            .as_ref()
            .expect("flexible links are prepared before the frames");
        let frame = cx.lookup_frame(&self.frame, ctx)?;
        Ok(flexible_energies(cx, link, &frame).into())
    }
}

impl Link {
    /// Builds the finite-element model and modes, and appends the modal
    /// coordinates `<name>_eta<j>`.
    fn build(
        &self,
        cx: &mut Context,
        coordinates: &mut Vec<Coordinate>,
        ctx: &str,
    ) -> Result<FlexibleLink, Error> {
        let (name, kind_at) = (&self.name, self.kind_at);
        let (frame, length, material, section, boundary) = (
            &self.frame,
            &self.length,
            &self.material,
            &self.section,
            &self.boundary,
        );
        let length = cx.constant_positive(length, ctx, "length")?;

        let material = cx.material(material, ctx)?;

        // Section.
        let sd = section.get_ref();
        let section_at = section.span().start;
        let section = match (&sd.radius, &sd.area, &sd.outer_radius, &sd.inner_radius) {
            (Some(r), None, None, None) => Section::circle(cx.constant_positive(r, ctx, "radius")?),
            (None, Some(a), None, None) => {
                Section::circle_with_area(cx.constant_positive(a, ctx, "area")?)
            }
            (None, None, Some(ro), Some(ri)) => {
                let ro_v = cx.constant_positive(ro, ctx, "outer radius")?;
                let ri_v = cx.constant_positive(ri, ctx, "inner radius")?;
                if ri_v >= ro_v {
                    return Err(cx.err(
                        ri.span().start,
                        Some(ctx),
                        format!("inner radius {ri_v} must be smaller than the outer radius {ro_v}"),
                    ));
                }
                Section::tube(ro_v, ri_v)
            }
            (None, None, Some(_), None) | (None, None, None, Some(_)) => {
                return Err(cx.err(
                    section_at,
                    Some(ctx),
                    "a tube section needs both `outer_radius` and `inner_radius`",
                ))
            }
            (None, None, None, None) => {
                return Err(cx.err(
                    section_at,
                    Some(ctx),
                    "the section needs `radius`, `area`, or `outer_radius` and `inner_radius`",
                ))
            }
            _ => {
                return Err(cx.err(
                    section_at,
                    Some(ctx),
                    "give one of `radius`, `area`, or `outer_radius` with `inner_radius`",
                ))
            }
        }
        .map_err(|e| cx.err(section_at, Some(ctx), e))?;

        let elements = match &self.elements {
            Some(n) => cx.constant_count(n, ctx, "elements", 1, MAX_ELEMENTS)?,
            None => 20,
        };
        let beam = Beam::new(length, material, section, elements)
            .map_err(|e| cx.err(kind_at, Some(ctx), e))?;

        // Boundary conditions.
        let b_at = boundary.span().start;
        let mut bc = match boundary.get_ref().as_str() {
            "pinned_pinned" | "pinned_pinned_elastic" => BoundaryConditions::pinned_pinned(),
            "clamped_free" => BoundaryConditions::clamped_free(),
            "clamped_clamped" => BoundaryConditions::clamped_clamped(),
            "free_free" => BoundaryConditions::free_free(),
            other => {
                return Err(cx.err(
                    b_at,
                    Some(ctx),
                    format!(
                        "unknown boundary `{other}` (known: pinned_pinned, clamped_free, \
                             clamped_clamped, free_free, pinned_pinned_elastic)"
                    ),
                ))
            }
        };
        let elastic = boundary.get_ref() == "pinned_pinned_elastic";
        match (&self.end_stiffness, elastic) {
            (Some(k), false) => {
                return Err(cx.err(
                    k.span().start,
                    Some(ctx),
                    "`end_stiffness` applies only to `boundary = \"pinned_pinned_elastic\"`",
                ))
            }
            (None, true) => {
                return Err(cx.err(
                    b_at,
                    Some(ctx),
                    "`pinned_pinned_elastic` needs `end_stiffness = [k_y, k_z]`",
                ))
            }
            (Some(k), true) => {
                let pair =
                    |b: &mut Context, v: &Spanned<Vec<SScalar>>| -> Result<[f64; 2], Error> {
                        if v.get_ref().len() != 2 {
                            return Err(b.err(
                                v.span().start,
                                Some(ctx),
                                format!(
                                    "end stiffness must be two numbers [k_y, k_z], found {}",
                                    v.get_ref().len()
                                ),
                            ));
                        }
                        let mut out = [0.0; 2];
                        for (o, s) in out.iter_mut().zip(v.get_ref()) {
                            *o = b.constant_value(s, ctx, "end stiffness")?;
                            if o.is_nan() || *o < 0.0 {
                                return Err(b.err(
                                    s.span().start,
                                    Some(ctx),
                                    format!("end stiffness must be non-negative, found {o}"),
                                ));
                            }
                        }
                        Ok(out)
                    };
                let (start, end) = match k.get_ref() {
                    EndStiffnessDef::Both(v) => {
                        let both = pair(cx, &Spanned::new(k.span(), v.clone()))?;
                        (Some(both), Some(both))
                    }
                    EndStiffnessDef::PerEnd(t) => {
                        let start = t.start.as_ref().map(|v| pair(cx, v)).transpose()?;
                        let end = t.end.as_ref().map(|v| pair(cx, v)).transpose()?;
                        (start, end)
                    }
                };
                if let Some([ky, kz]) = start {
                    bc.start = bc.start.with_spring(RY, ky).with_spring(RZ, kz);
                }
                if let Some([ky, kz]) = end {
                    bc.end = bc.end.with_spring(RY, ky).with_spring(RZ, kz);
                }
            }
            (None, false) => {}
        }
        let fe = FeModel::new(&beam, &bc).map_err(|e| cx.err(b_at, Some(ctx), e))?;
        let all = fe.modes().map_err(|e| cx.err(b_at, Some(ctx), e))?;

        // Modes kept.
        let selection = match (&self.modes, &self.max_frequency) {
            (Some(_), Some(f)) => {
                return Err(cx.err(
                    f.span().start,
                    Some(ctx),
                    "give either `modes` or `max_frequency`, not both",
                ))
            }
            (Some(k), None) => {
                let n = cx.constant_count(k, ctx, "modes", 0, MAX_MODES)?;
                if n > all.len() {
                    return Err(cx.err(
                        k.span().start,
                        Some(ctx),
                        format!(
                            "{n} modes asked for, but the mesh of {elements} elements has only {} \
                                 elastic modes",
                            all.len()
                        ),
                    ));
                }
                ModeSelection::First(n)
            }
            (None, Some(f)) => {
                ModeSelection::BelowHz(cx.constant_positive(f, ctx, "max_frequency")?)
            }
            (None, None) => ModeSelection::First(6.min(all.len())),
        };
        let basis = all.select(selection);
        if basis.len() > MAX_MODES {
            let at = self
                .max_frequency
                .as_ref()
                .map_or(kind_at, |f| f.span().start);
            return Err(cx.err(
                at,
                Some(ctx),
                format!(
                    "{} modes lie below max_frequency; at most {MAX_MODES} are supported",
                    basis.len()
                ),
            ));
        }
        let k = basis.len();
        let invariants = Invariants::new(&fe, &basis);

        // Damping.
        let damping_ratio = match &self.damping_ratio {
            None => vec![0.0; k],
            Some(d) => {
                let at = d.span().start;
                let values: Vec<(f64, usize)> = match d.get_ref() {
                    ScalarList::One(v) => {
                        let s = Spanned::new(d.span(), v.clone());
                        let z = cx.constant_value(&s, ctx, "damping ratio")?;
                        vec![(z, at); k]
                    }
                    ScalarList::Many(list) => {
                        if list.len() != k {
                            return Err(cx.err(
                                at,
                                Some(ctx),
                                format!(
                                    "damping_ratio has {} values but {k} modes are kept \
                                         (give one value for all modes, or one per mode)",
                                    list.len()
                                ),
                            ));
                        }
                        let mut out = Vec::with_capacity(k);
                        for s in list {
                            let z = cx.constant_value(s, ctx, "damping ratio")?;
                            out.push((z, s.span().start));
                        }
                        out
                    }
                };
                let mut out = Vec::with_capacity(k);
                for (z, at) in values {
                    if z.is_nan() || z < 0.0 {
                        return Err(cx.err(
                            at,
                            Some(ctx),
                            format!("damping ratio must be non-negative, found {z}"),
                        ));
                    }
                    out.push(z);
                }
                out
            }
        };

        // Centrifugal stiffening.
        let geometric_stiffness = match &self.geometric_stiffening {
            Some(g) if *g.get_ref() => {
                if !bc.start.fixed[UX] || bc.end.fixed[UX] {
                    return Err(cx.err(
                            g.span().start,
                            Some(ctx),
                            format!(
                                "geometric_stiffening is supported only for links held axially at \
                                 the start and free axially at the end (clamped_free, pinned_pinned, \
                                 pinned_pinned_elastic), not `{}`",
                                boundary.get_ref()
                            ),
                        ));
                }
                let rho_a = beam.mass_per_length();
                let kg = fe.geometric_stiffness(|x| 0.5 * rho_a * (length * length - x * x));
                Some(basis.project(&kg))
            }
            _ => None,
        };

        // Modal coordinates.
        let name_at = self.name_at;
        let first_coordinate = coordinates.len();
        let g0 = 9.81;
        for j in 0..k {
            let cname = format!("{name}_eta{}", j + 1);
            if coordinates.iter().any(|o| o.name == cname)
                || cx.scope.parameters.contains_key(&cname)
            {
                return Err(cx.err(
                    name_at,
                    Some(ctx),
                    format!(
                        "the modal coordinate `{cname}` of this link has the name of a \
                             coordinate or parameter declared already"
                    ),
                ));
            }
            let w = basis.omega[j];
            let amplitude = 10.0 * g0 * invariants.mass.sqrt() / (w * w);
            coordinates.push(Coordinate {
                name: cname.clone(),
                range: Some([-amplitude, amplitude]),
                velocity_range: Some([-w * amplitude, w * amplitude]),
                initial: 0.0,
                initial_velocity: 0.0,
            });
            cx.scope.coordinates.push(cname);
        }
        Ok(FlexibleLink {
            name: name.clone(),
            frame: frame.get_ref().clone(),
            first_coordinate,
            fe,
            basis,
            invariants,
            damping_ratio,
            geometric_stiffness,
        })
    }
}

/// The frame that follows a flexible link at a station: origin at the
/// deformed centre line `u0(x) + Phi_t(x) eta`, axes rotated by the small
/// elastic rotation `theta = Phi_r(x) eta` as elementary rotations about
/// x, y, z in turn (orthogonal; `I + skew(theta)` to first order).
pub(in crate::model) fn station_frame(
    cx: &mut Context,
    f: &FrameDef,
    station: &SScalar,
    parent: &Frame,
    ctx: &str,
) -> Result<Frame, Error> {
    let at = station.span().start;
    let Some(parent_name) = &f.parent else {
        return Err(cx.err(
            at,
            Some(ctx),
            "a `station` needs `parent`: the reference frame of a flexible link",
        ));
    };
    let links: Vec<usize> = (0..cx.flexible.len())
        .filter(|&i| cx.flexible[i].frame == *parent_name.get_ref())
        .collect();
    let link = match links.as_slice() {
        [i] => *i,
        [] => {
            return Err(cx.err(
                at,
                Some(ctx),
                format!(
                "frame `{}` is not the reference frame of a flexible link, so it has no stations",
                parent_name.get_ref()
            ),
            ))
        }
        _ => {
            let names: Vec<&str> = links
                .iter()
                .map(|&i| cx.flexible[i].name.as_str())
                .collect();
            return Err(cx.err(
                at,
                Some(ctx),
                format!(
                    "frame `{}` is the reference frame of several flexible links ({}); give each its own frame",
                    parent_name.get_ref(),
                    names.join(", ")
                ),
            ));
        }
    };
    let length = cx.flexible[link].basis.beam.length;
    let x = match station.get_ref() {
        Scalar::Expr(e) if e.trim() == "start" => 0.0,
        Scalar::Expr(e) if e.trim() == "end" => length,
        _ => cx.constant_value(station, ctx, "station")?,
    };
    if !(x >= 0.0 && x <= length * (1.0 + 1e-12)) {
        return Err(cx.err(
            at,
            Some(ctx),
            format!(
                "station x = {x} is outside the link `{}` (0 to {length})",
                cx.flexible[link].name
            ),
        ));
    }
    let link = &cx.flexible[link];
    let st = link
        .basis
        .station(x.min(length))
        .map_err(|e| cx.err(at, Some(ctx), e))?;
    let first = link.first_coordinate;
    let eta: Vec<Id> = (0..st.translation.ncols())
        .map(|j| cx.graph.q(first + j))
        .collect();
    let row = |m: &DMatrix<f64>, a: usize| -> Vec<f64> { m.row(a).iter().copied().collect() };
    let (tr, rot) = (st.translation.clone(), st.rotation.clone());
    let translation: [Id; 3] = std::array::from_fn(|a| {
        let u0 = if a == 0 { x } else { 0.0 };
        let coeffs = row(&tr, a);
        modal_linear(&mut cx.graph, u0, &coeffs, &eta)
    });
    let mut rotations = Vec::new();
    for a in 0..3 {
        let coeffs = row(&rot, a);
        let angle = modal_linear(&mut cx.graph, 0.0, &coeffs, &eta);
        if !cx.graph.is_const(angle, 0.0) {
            let mut axis = [0.0; 3];
            axis[a] = 1.0;
            rotations.push((axis, angle));
        }
    }
    Ok(cx.child_frame(parent, translation, &rotations))
}

/// `constant + sum_j coeffs[j] vars[j]`, dropping the coefficients below
/// `1e-14` of the largest (round-off of entries that are zero).
fn modal_linear(g: &mut Graph, constant: f64, coeffs: &[f64], vars: &[Id]) -> Id {
    let scale = coeffs.iter().fold(0.0f64, |m, c| m.max(c.abs()));
    let terms: Vec<(Id, f64)> = coeffs
        .iter()
        .zip(vars)
        .filter(|(c, _)| c.abs() > 1e-14 * scale)
        .map(|(&c, &v)| (v, c))
        .collect();
    g.linear(&terms, constant)
}

/// `sum_ij q[i][j] a_i b_j`, dropping entries below `1e-14 * scale`.
fn modal_bilinear(g: &mut Graph, q: &DMatrix<f64>, a: &[Id], b: &[Id], scale: f64) -> Id {
    let mut terms = Vec::new();
    for i in 0..q.nrows() {
        for j in 0..q.ncols() {
            let v = q[(i, j)];
            if v.abs() > 1e-14 * scale {
                terms.push((g.mul(a[i], b[j]), v));
            }
        }
    }
    g.linear(&terms, 0.0)
}

/// `sum_ij q[i][j] a_i a_j`, dropping the entries below `1e-14` of
/// `bound[i][j]`.
fn modal_projected(g: &mut Graph, q: &DMatrix<f64>, bound: &DMatrix<f64>, a: &[Id]) -> Id {
    let mut terms = Vec::new();
    for i in 0..q.nrows() {
        for j in 0..q.ncols() {
            let v = q[(i, j)];
            if v.abs() > 1e-14 * bound[(i, j)] {
                terms.push((g.mul(a[i], a[j]), v));
            }
        }
    }
    g.linear(&terms, 0.0)
}

/// `T`, `V` and `D` of a flexible link in the floating frame of
/// reference (see the [`crate::fem`] module docs for the formulas).
#[allow(clippy::needless_range_loop)]
fn flexible_energies(cx: &mut Context, link: &FlexibleLink, frame: &Frame) -> [Id; 3] {
    let inv = &link.invariants;
    let k = link.modes();
    let eta: Vec<Id> = (0..k)
        .map(|j| cx.graph.q(link.first_coordinate + j))
        .collect();
    let etad: Vec<Id> = (0..k)
        .map(|j| cx.graph.qd(link.first_coordinate + j))
        .collect();
    let amax = |m: &DMatrix<f64>| m.amax();
    let s1_scale = amax(&inv.s1);
    let i1_scale = inv.i1.iter().flatten().fold(0.0f64, |m, v| m.max(v.amax()));
    let i2_scale = inv.i2.iter().flatten().fold(0.0f64, |m, v| m.max(v.amax()));
    let drop = |v: f64, scale: f64| if v.abs() > 1e-14 * scale { v } else { 0.0 };
    // First moment c(eta) = S0 + S1 eta.
    let c: [Id; 3] = std::array::from_fn(|a| {
        let coeffs: Vec<f64> = (0..k).map(|j| drop(inv.s1[(a, j)], s1_scale)).collect();
        modal_linear(&mut cx.graph, inv.s0[a], &coeffs, &eta)
    });
    // Second moments J_ab(eta).
    let i0_scale = inv.i0.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut j = [[cx.graph.constant(0.0); 3]; 3];
    for a in 0..3 {
        for b in a..3 {
            let coeffs: Vec<f64> = (0..k)
                .map(|m| drop(inv.i1[a][b][m] + inv.i1[b][a][m], i1_scale))
                .collect();
            let lin = modal_linear(&mut cx.graph, drop(inv.i0[a][b], i0_scale), &coeffs, &eta);
            let quad = modal_bilinear(&mut cx.graph, &inv.i2[a][b], &eta, &eta, i2_scale);
            j[a][b] = cx.graph.add(lin, quad);
            j[b][a] = j[a][b];
        }
    }
    let trace = cx.graph.sum(&[j[0][0], j[1][1], j[2][2]]);
    let theta: [[Id; 3]; 3] = std::array::from_fn(|a| {
        std::array::from_fn(|b| {
            if a == b {
                cx.graph.sub(trace, j[a][a])
            } else {
                cx.graph.neg(j[a][b])
            }
        })
    });
    // h = sum eps_abc (I1[b][c].eta_dot + eta^T I2[b][c] eta_dot).
    let mut g = [[cx.graph.constant(0.0); 3]; 3];
    for b in 0..3 {
        for cc in 0..3 {
            if b == cc {
                continue;
            }
            let coeffs: Vec<f64> = (0..k).map(|m| drop(inv.i1[b][cc][m], i1_scale)).collect();
            let lin = modal_linear(&mut cx.graph, 0.0, &coeffs, &etad);
            let quad = modal_bilinear(&mut cx.graph, &inv.i2[b][cc], &eta, &etad, i2_scale);
            g[b][cc] = cx.graph.add(lin, quad);
        }
    }
    let h = [
        cx.graph.sub(g[1][2], g[2][1]),
        cx.graph.sub(g[2][0], g[0][2]),
        cx.graph.sub(g[0][1], g[1][0]),
    ];
    let (v, w) = (frame.velocity, frame.omega);
    let m = cx.graph.constant(inv.mass);
    let vv = cx.graph.dot(v, v);
    let t_trans = cx.graph.mul(m, vv);
    let wc = cx.graph.cross(w, c);
    let t_coupling = cx.graph.dot(v, wc);
    let mut rot_terms = Vec::new();
    for a in 0..3 {
        for b in 0..3 {
            let ww = cx.graph.mul(w[a], w[b]);
            rot_terms.push((cx.graph.mul(ww, theta[a][b]), 0.5));
        }
    }
    let t_rot = cx.graph.linear(&rot_terms, 0.0);
    let s1_ed: [Id; 3] = std::array::from_fn(|a| {
        let coeffs: Vec<f64> = (0..k).map(|j| drop(inv.s1[(a, j)], s1_scale)).collect();
        modal_linear(&mut cx.graph, 0.0, &coeffs, &etad)
    });
    let t_vf = cx.graph.dot(v, s1_ed);
    let t_wh = cx.graph.dot(w, h);
    // Mff and Kff are projections Phi^T A Phi of the whole mesh's
    // matrices: an entry is round-off of zero when it is below 1e-14 of
    // the sum of the absolute values of its products,
    // (|Phi|^T |A| |Phi|)_ij (the off-diagonal entries of the
    // orthogonal modes, mathematically zero).
    let abs_phi = link.basis.shapes.abs();
    let bound = |a: &DMatrix<f64>| abs_phi.transpose() * a.abs() * &abs_phi;
    let mff_bound = bound(&link.fe.mass);
    let kff_bound = bound(&link.fe.stiffness);
    let t_ff = modal_projected(&mut cx.graph, &inv.mff, &mff_bound, &etad);
    let mut kinetic = cx.graph.linear(
        &[
            (t_trans, 0.5),
            (t_coupling, 1.0),
            (t_rot, 1.0),
            (t_vf, 1.0),
            (t_wh, 1.0),
            (t_ff, 0.5),
        ],
        0.0,
    );
    if let Some(kg) = &link.geometric_stiffness {
        // Centrifugal stiffening, a velocity-dependent potential
        // 1/2 (w_y^2 + w_z^2) eta^T Kg1 eta, enters the Lagrangian T - V
        // as part of T with a minus sign.
        let stiff = modal_bilinear(&mut cx.graph, kg, &eta, &eta, kg.amax());
        let wy2 = cx.graph.powi(w[1], 2);
        let wz2 = cx.graph.powi(w[2], 2);
        let spin = cx.graph.add(wy2, wz2);
        let u = cx.graph.mul(spin, stiff);
        kinetic = cx.graph.linear(&[(kinetic, 1.0), (u, -0.5)], 0.0);
    }
    // Strain and gravity: 1/2 eta^T Kff eta - g.(m R + A c(eta)).
    let strain = modal_projected(&mut cx.graph, &inv.kff, &kff_bound, &eta);
    let ac = cx.graph.rotate(&frame.rotation, c);
    let mr: [Id; 3] = std::array::from_fn(|a| {
        let mo = cx.graph.mul(m, frame.origin[a]);
        cx.graph.add(mo, ac[a])
    });
    let gp = cx.graph.dot(cx.gravity, mr);
    let potential = cx.graph.linear(&[(strain, 0.5), (gp, -1.0)], 0.0);
    // Modal damping: D = sum zeta_j w_j eta_dot_j^2.
    let mut d_terms = Vec::new();
    for (jj, &z) in link.damping_ratio.iter().enumerate() {
        if z > 0.0 {
            let e2 = cx.graph.powi(etad[jj], 2);
            d_terms.push((e2, z * link.basis.omega[jj]));
        }
    }
    let dissipation = cx.graph.linear(&d_terms, 0.0);
    [kinetic, potential, dissipation]
}
