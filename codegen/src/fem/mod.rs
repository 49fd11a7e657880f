//! Finite-element foundation for flexible links in the floating frame of
//! reference formulation (FFRF).
//!
//! A straight 3D Euler-Bernoulli beam is discretised at generation time by
//! `n` equal two-node elements, constrained as it is joined
//! ([`BoundaryConditions`]), reduced to a few normal modes ([`ModalBasis`])
//! and condensed into the shape integrals ("inertia invariants",
//! [`Invariants`]) from which the kinetic energy of the flexible link is a
//! polynomial in its modal coordinates. Everything here is plain `f64`
//! numerics; the symbolic side lives elsewhere.
//!
//! # Conventions
//!
//! Local frame: `x` along the beam from `x = 0` (node 0, "start") to `x = L`
//! (node `n`, "end"); nodes at `x_i = i h`, `h = L / n`. Six dofs per node,
//! in the order [`UX`], [`UY`], [`UZ`], [`RX`], [`RY`], [`RZ`]; node `i`'s dof
//! `d` has global index `6 i + d`. Rotations are small rotation vectors: `rx`
//! is the twist, and for the centre-line displacements `v = uy`, `w = uz`,
//! `rz = dv/dx` and `ry = -dw/dx` (right-hand rule).
//!
//! # Element (12 dofs, [`element`])
//!
//! With `xi = (x - x_a) / h` and the cubic Hermite functions
//! `H1 = 1 - 3 xi^2 + 2 xi^3`, `H2 = h (xi - 2 xi^2 + xi^3)`,
//! `H3 = 3 xi^2 - 2 xi^3`, `H4 = h (xi^3 - xi^2)`:
//!
//! - axial `ux = (1 - xi) ux_a + xi ux_b`, twist `rx = (1 - xi) rx_a + xi rx_b`;
//! - bending in the x-y plane `v = H1 uy_a + H2 rz_a + H3 uy_b + H4 rz_b`;
//! - bending in the x-z plane `w = H1 uz_a - H2 ry_a + H3 uz_b - H4 ry_b`.
//!
//! Stiffness: `EA/h [1 -1; -1 1]` (axial), `GJ/h [1 -1; -1 1]` (torsion),
//! `EI/h^3 [12 6h -12 6h; 6h 4h^2 -6h 2h^2; -12 -6h 12 -6h; 6h 2h^2 -6h 4h^2]`
//! per bending plane in `(u, theta, u, theta)` with `theta = du/dx` (`EIz` for
//! x-y, `EIy` for x-z, signs of `ry` flipped). Consistent mass:
//! `rho A h/6 [2 1; 1 2]` (axial), `rho Ip h/6 [2 1; 1 2]` (torsional
//! inertia), `rho A h/420 [156 22h 54 -13h; 22h 4h^2 13h -3h^2; 54 13h 156
//! -22h; -13h -3h^2 -22h 4h^2]` per bending plane. These are exactly
//! `int rho A N^T N dx + int rho Ip N_rx^T N_rx dx` for the shape functions
//! above; the rotary inertia of the bending sections (`rho I`) is neglected
//! (Euler-Bernoulli). Geometric stiffness for an axial force `N` (tension
//! positive), from `1/2 int N (v'^2 + w'^2) dx`:
//! `N/(30 h) [36 3h -36 3h; 3h 4h^2 -3h -h^2; -36 -3h 36 -3h; 3h -h^2 -3h 4h^2]`
//! per bending plane (nothing on the axial and torsion dofs).
//!
//! # Boundary conditions ([`BoundaryConditions`])
//!
//! Each end fixes some of its six dofs and may add grounded springs
//! (stiffness added to the diagonal of `K`). In the FFRF the reference frame
//! carries the rigid motion, so the conditions must remove all six
//! rigid-body modes; every preset except free-free does (`K` restricted to
//! the free dofs is positive definite):
//!
//! | preset | start (x = 0) fixed | end (x = L) fixed | springs |
//! |---|---|---|---|
//! | [`clamped_free`](BoundaryConditions::clamped_free) | all six | none | - |
//! | [`pinned_pinned`](BoundaryConditions::pinned_pinned) | ux uy uz rx | uy uz | - |
//! | [`pinned_pinned_elastic`](BoundaryConditions::pinned_pinned_elastic) | ux uy uz rx | uy uz | `k_y` on ry, `k_z` on rz, both ends |
//! | [`clamped_clamped`](BoundaryConditions::clamped_clamped) | all six | all six | - |
//! | [`free_free`](BoundaryConditions::free_free) | none | none | - |
//!
//! Pinned-pinned: the start point is the frame origin (ux uy uz fixed), the
//! frame `x` axis passes through the end point (uy uz fixed at `L`, which
//! removes the rotations about `y` and `z`), and the twist is measured from
//! the start section (rx fixed at 0, removing the rotation about `x`). The
//! end is free axially and in twist, so axial and torsional modes are those
//! of a fixed-free bar. The elastic constraint adds rotational springs on
//! both bending rotations at both ends: `k -> 0` is pinned-pinned, `k -> inf`
//! clamps the bending rotations (clamped-clamped bending). Free-free keeps
//! the six rigid-body modes in `K`; the modal solver drops them (their
//! number is found from the rigid-body vectors, [`FeModel::rigid_body_count`])
//! and the elastic modes are then mass-orthogonal to rigid motion (mean-axis
//! conditions: `S1 = 0` and `int rho A u0 x u_f dx = 0`).
//!
//! Joint stiffness ([`shaft_joint_stiffness`]): a flexible joint member of
//! mass `m_j`, length `l_j`, density `rho`, treated as a solid circular shaft
//! along the joint axis, has `A = m_j / (rho l_j)`, `r = sqrt(A / pi)`,
//! `Ip = pi r^4 / 2`, `I = pi r^4 / 4`; twisting it about its own axis (the
//! joint axis) gives `k_t = G Ip / l_j`, bending it by an end moment with the
//! other end clamped gives `k_b = E I / l_j`. For the spec's joint
//! (0.07 kg, 0.04 m, 2740 kg/m^3, E = 2.07e11 Pa, nu = 0.33):
//! `k_t ~ 1.26e5 N m/rad`, `k_b ~ 1.68e5 N m/rad`.
//!
//! # Modes ([`modal`])
//!
//! `K phi = w^2 M phi` on the free dofs: Cholesky `M = L L^T`, symmetric
//! eigen-decomposition of `L^-1 K L^-T`, `phi = L^-T y` (so `phi^T M phi =
//! I`), sorted by frequency, expanded to all dofs with zeros at the fixed
//! ones. The free dofs are first split into the independent blocks of the
//! sparsity pattern of `K + M` (axial, torsion, and the two bending planes for
//! a straight beam), which makes each mode pure and the solve fast; each
//! mode's sign is fixed (largest entry positive) so that results are
//! reproducible. Equal frequencies (the two bending planes of a round
//! section) are ordered x-y plane first.
//!
//! # Invariants ([`invariants`])
//!
//! Undeformed centre line `u0(x) = (x, 0, 0)`, elastic displacement
//! `u_f(x) = N(x) e` (centre-line translations only, `N` the 3 x dofs
//! interpolation above) with `e = Phi eta`; `N_a` is row `a` of `N`. All
//! integrals are over `[0, L]`, computed per element by 4-point
//! Gauss-Legendre quadrature, exact for these polynomial integrands (degree
//! <= 6):
//!
//! - `m = int rho A dx`, `S0 = int rho A u0 dx`, `S1 = int rho A N Phi dx` (3 x k);
//! - `I0_ab = int rho A u0_a u0_b dx` (3 x 3);
//! - `I1[a][b] = int rho A u0_a (N_b Phi) dx` (k-vector);
//! - `I2[a][b] = int rho A (N_a Phi)^T (N_b Phi) dx` (k x k, `I2[b][a] = I2[a][b]^T`);
//! - `Mff = Phi^T M Phi` (= I), `Kff = Phi^T K Phi` (= diag w^2, including
//!   the boundary springs).
//!
//! With `V` the velocity of the frame origin and `w` the angular velocity of
//! the frame (both in frame axes), and `u = u0 + u_f` the position of a
//! centre-line point relative to the frame origin, the kinetic energy
//!
//! `T = 1/2 int rho A |V + w x u + u_f_dot|^2 dx + 1/2 int rho Ip rx_dot^2 dx`
//!
//! is assembled from the invariants as (`invariants::kinetic_energy`, the
//! tests' reference, evaluates it):
//!
//! ```text
//! c(eta)     = S0 + S1 eta                                    (first moment)
//! J_ab(eta)  = I0_ab + I1[a][b].eta + I1[b][a].eta + eta^T I2[a][b] eta
//! Theta(eta) = trace(J) 1 - J                                 (inertia tensor)
//! h_a        = sum_{b,c} eps_abc (I1[b][c].eta_dot + eta^T I2[b][c] eta_dot)
//!
//! T = 1/2 m V.V + V.(w x c) + 1/2 w^T Theta w
//!   + V.(S1 eta_dot) + w.h + 1/2 eta_dot^T Mff eta_dot
//! ```
//!
//! (`h = int rho A u x u_f_dot dx`; the last term carries both
//! `int rho A |u_f_dot|^2 = eta_dot^T (sum_a I2[a][a]) eta_dot` and the
//! torsional inertia `int rho Ip rx_dot^2`.) The strain energy is
//! `U = 1/2 eta^T Kff eta`, plus `1/2 eta^T (Phi^T Kg Phi) eta` for an axial
//! force field `N(x)` ([`FeModel::geometric_stiffness`]); for a link spinning
//! at rate `W` about a transverse axis through `x = 0` with a free end,
//! `N(x) = rho A W^2 (L^2 - x^2) / 2`, so the stiffening is `W^2` times the
//! projection for `N1(x) = rho A (L^2 - x^2) / 2`. Gravity needs only `m`,
//! `c(eta)`. Joint points use the rows of `Phi` at the end nodes
//! ([`Invariants::start`], [`Invariants::end`], [`ModalBasis::station`]).
//! Not included: the sections' own rotary inertia about the frame axes
//! (`rho Ip`, `rho Iy`, `rho Iz` times `w`), negligible for slender links.

#![allow(clippy::needless_range_loop)]

pub mod element;
pub mod invariants;
pub mod modal;

use nalgebra::{DMatrix, DVector};

#[cfg(test)]
mod frequency_tests;

#[cfg(test)]
pub use invariants::kinetic_energy;
pub use invariants::Invariants;
pub use modal::{ModalBasis, ModeSelection};

/// Axial displacement dof (index within a node).
pub const UX: usize = 0;
/// Transverse displacement along `y`.
pub const UY: usize = 1;
/// Transverse displacement along `z`.
pub const UZ: usize = 2;
/// Twist (small rotation about `x`).
pub const RX: usize = 3;
/// Small rotation about `y` (`-dw/dx` on the centre line).
pub const RY: usize = 4;
/// Small rotation about `z` (`dv/dx` on the centre line).
pub const RZ: usize = 5;
/// Dofs per node.
pub const NODE_DOFS: usize = 6;

fn check_positive(name: &str, value: f64) -> Result<(), String> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(format!("{name} must be positive and finite, got {value}"))
    }
}

/// Linear elastic isotropic material.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Material {
    /// Young's modulus `E` (Pa).
    pub youngs_modulus: f64,
    /// Shear modulus `G` (Pa).
    pub shear_modulus: f64,
    /// Density `rho` (kg/m^3).
    pub density: f64,
}

impl Material {
    /// From `E`, Poisson's ratio `nu` (in `(-1, 0.5)`) and `rho`, with
    /// `G = E / (2 (1 + nu))`.
    pub fn new(youngs_modulus: f64, poisson: f64, density: f64) -> Result<Material, String> {
        check_positive("Young's modulus", youngs_modulus)?;
        check_positive("density", density)?;
        if !(poisson.is_finite() && poisson > -1.0 && poisson < 0.5) {
            return Err(format!(
                "Poisson's ratio must lie in (-1, 0.5), got {poisson}"
            ));
        }
        Ok(Material {
            youngs_modulus,
            shear_modulus: youngs_modulus / (2.0 * (1.0 + poisson)),
            density,
        })
    }

    /// From `E`, `G` and `rho` directly.
    pub fn with_shear_modulus(
        youngs_modulus: f64,
        shear_modulus: f64,
        density: f64,
    ) -> Result<Material, String> {
        check_positive("Young's modulus", youngs_modulus)?;
        check_positive("shear modulus", shear_modulus)?;
        check_positive("density", density)?;
        Ok(Material {
            youngs_modulus,
            shear_modulus,
            density,
        })
    }
}

/// Cross-section properties, in the section's principal axes `y`, `z`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Section {
    /// Area `A` (m^2).
    pub area: f64,
    /// Second moment about `y`, `Iy = int z^2 dA` (bending in the x-z plane).
    pub iy: f64,
    /// Second moment about `z`, `Iz = int y^2 dA` (bending in the x-y plane).
    pub iz: f64,
    /// Torsion constant `J` (stiffness `G J`).
    pub torsion_constant: f64,
    /// Polar moment `Ip = Iy + Iz` (torsional inertia `rho Ip`).
    pub polar: f64,
}

impl Section {
    /// Solid circle of radius `r`: `A = pi r^2`, `Iy = Iz = pi r^4 / 4`,
    /// `J = Ip = pi r^4 / 2`.
    pub fn circle(radius: f64) -> Result<Section, String> {
        check_positive("radius", radius)?;
        let i = std::f64::consts::PI * radius.powi(4) / 4.0;
        Ok(Section {
            area: std::f64::consts::PI * radius * radius,
            iy: i,
            iz: i,
            torsion_constant: 2.0 * i,
            polar: 2.0 * i,
        })
    }

    /// Solid circle of area `A` (radius `sqrt(A / pi)`).
    pub fn circle_with_area(area: f64) -> Result<Section, String> {
        check_positive("area", area)?;
        Section::circle((area / std::f64::consts::PI).sqrt())
    }

    /// Circular tube: `A = pi (ro^2 - ri^2)`, `Iy = Iz = pi (ro^4 - ri^4) / 4`,
    /// `J = Ip = pi (ro^4 - ri^4) / 2`.
    pub fn tube(outer_radius: f64, inner_radius: f64) -> Result<Section, String> {
        check_positive("outer radius", outer_radius)?;
        check_positive("inner radius", inner_radius)?;
        if inner_radius >= outer_radius {
            return Err(format!(
                "inner radius {inner_radius} must be smaller than outer radius {outer_radius}"
            ));
        }
        let pi = std::f64::consts::PI;
        let i = pi * (outer_radius.powi(4) - inner_radius.powi(4)) / 4.0;
        Ok(Section {
            area: pi * (outer_radius * outer_radius - inner_radius * inner_radius),
            iy: i,
            iz: i,
            torsion_constant: 2.0 * i,
            polar: 2.0 * i,
        })
    }

    /// Any section from its five properties, all positive.
    pub fn general(
        area: f64,
        iy: f64,
        iz: f64,
        torsion_constant: f64,
        polar: f64,
    ) -> Result<Section, String> {
        check_positive("area", area)?;
        check_positive("Iy", iy)?;
        check_positive("Iz", iz)?;
        check_positive("torsion constant", torsion_constant)?;
        check_positive("polar moment", polar)?;
        Ok(Section {
            area,
            iy,
            iz,
            torsion_constant,
            polar,
        })
    }
}

/// A straight uniform beam and its mesh of equal elements.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beam {
    /// Length `L` (m).
    pub length: f64,
    /// Material.
    pub material: Material,
    /// Cross-section.
    pub section: Section,
    /// Number of equal elements `n` (`n + 1` nodes).
    pub elements: usize,
}

impl Beam {
    /// A beam of length `L` meshed with `elements >= 1` equal elements.
    pub fn new(
        length: f64,
        material: Material,
        section: Section,
        elements: usize,
    ) -> Result<Beam, String> {
        check_positive("beam length", length)?;
        if elements == 0 {
            return Err("a beam needs at least one element".to_string());
        }
        Ok(Beam {
            length,
            material,
            section,
            elements,
        })
    }

    /// Element length `h = L / n`.
    pub fn element_length(&self) -> f64 {
        self.length / self.elements as f64
    }

    /// Number of nodes, `n + 1`.
    pub fn nodes(&self) -> usize {
        self.elements + 1
    }

    /// Number of dofs, `6 (n + 1)`.
    pub fn dofs(&self) -> usize {
        NODE_DOFS * self.nodes()
    }

    /// Mass per unit length `rho A`.
    pub fn mass_per_length(&self) -> f64 {
        self.material.density * self.section.area
    }
}

/// Rotational stiffnesses of a flexible joint member treated as a solid
/// circular shaft along the joint axis (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShaftJoint {
    /// `k_t = G Ip / l`, about the joint (shaft) axis (N m/rad).
    pub torsional: f64,
    /// `k_b = E I / l`, about the two axes transverse to the shaft (N m/rad).
    pub bending: f64,
}

/// Stiffness of a joint member of mass `mass` and length `length` made of
/// `material`: `A = m / (rho l)`, solid circle of that area,
/// `k_t = G Ip / l`, `k_b = E I / l`.
pub fn shaft_joint_stiffness(
    material: &Material,
    mass: f64,
    length: f64,
) -> Result<ShaftJoint, String> {
    check_positive("joint mass", mass)?;
    check_positive("joint length", length)?;
    let section = Section::circle_with_area(mass / (material.density * length))?;
    Ok(ShaftJoint {
        torsional: material.shear_modulus * section.polar / length,
        bending: material.youngs_modulus * section.iz / length,
    })
}

/// How one end of the beam is joined: which of its six dofs are fixed, and
/// grounded springs on the others.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct EndCondition {
    /// `fixed[d]`: dof `d` ([`UX`]..[`RZ`]) of the end node is held at zero.
    pub fixed: [bool; 6],
    /// Spring stiffness added to `K[d][d]` of the end node (N/m or N m/rad);
    /// zero for none. Ignored on fixed dofs.
    pub springs: [f64; 6],
}

impl EndCondition {
    /// Nothing fixed, no springs.
    pub fn free() -> EndCondition {
        EndCondition::default()
    }

    /// All six dofs fixed.
    pub fn clamped() -> EndCondition {
        EndCondition {
            fixed: [true; 6],
            springs: [0.0; 6],
        }
    }

    /// The given dofs fixed, no springs.
    pub fn fixing(dofs: &[usize]) -> EndCondition {
        let mut end = EndCondition::free();
        for &d in dofs {
            end.fixed[d] = true;
        }
        end
    }

    /// This condition with a spring of stiffness `k` on dof `d`.
    pub fn with_spring(mut self, dof: usize, stiffness: f64) -> EndCondition {
        self.springs[dof] = stiffness;
        self
    }

    /// Whether dof `d` is fixed or sprung (restrains rigid motion).
    fn restrains(&self, d: usize) -> bool {
        self.fixed[d] || self.springs[d] > 0.0
    }
}

/// Boundary conditions of the beam at its two ends (see the module docs
/// for the presets and why each removes the rigid-body modes).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoundaryConditions {
    /// End at `x = 0` (node 0).
    pub start: EndCondition,
    /// End at `x = L` (node `n`).
    pub end: EndCondition,
}

impl BoundaryConditions {
    /// Clamped at `x = 0`, free at `x = L` (cantilever).
    pub fn clamped_free() -> BoundaryConditions {
        BoundaryConditions {
            start: EndCondition::clamped(),
            end: EndCondition::free(),
        }
    }

    /// Simply supported, FFRF style: ux uy uz rx fixed at `x = 0`, uy uz at
    /// `x = L`.
    pub fn pinned_pinned() -> BoundaryConditions {
        BoundaryConditions {
            start: EndCondition::fixing(&[UX, UY, UZ, RX]),
            end: EndCondition::fixing(&[UY, UZ]),
        }
    }

    /// Pinned-pinned with rotational springs at both ends: `k_y` on the
    /// rotation about `y` (x-z bending), `k_z` about `z` (x-y bending).
    pub fn pinned_pinned_elastic(k_y: f64, k_z: f64) -> BoundaryConditions {
        let pp = BoundaryConditions::pinned_pinned();
        BoundaryConditions {
            start: pp.start.with_spring(RY, k_y).with_spring(RZ, k_z),
            end: pp.end.with_spring(RY, k_y).with_spring(RZ, k_z),
        }
    }

    /// Both ends clamped.
    pub fn clamped_clamped() -> BoundaryConditions {
        BoundaryConditions {
            start: EndCondition::clamped(),
            end: EndCondition::clamped(),
        }
    }

    /// Nothing fixed: six rigid-body modes, dropped by the modal solver.
    pub fn free_free() -> BoundaryConditions {
        BoundaryConditions {
            start: EndCondition::free(),
            end: EndCondition::free(),
        }
    }

    fn validate(&self) -> Result<(), String> {
        for (name, end) in [("start", &self.start), ("end", &self.end)] {
            for (d, &k) in end.springs.iter().enumerate() {
                if !(k.is_finite() && k >= 0.0) {
                    return Err(format!(
                        "spring stiffness on dof {d} at the {name} must be finite and >= 0, got {k}"
                    ));
                }
            }
        }
        Ok(())
    }
}

/// An assembled, constrained finite-element model of a beam.
#[derive(Debug, Clone)]
pub struct FeModel {
    /// The beam.
    pub beam: Beam,
    /// Its boundary conditions.
    pub bc: BoundaryConditions,
    /// Global consistent mass matrix, all `6 (n + 1)` dofs.
    pub mass: DMatrix<f64>,
    /// Global stiffness matrix, all dofs, boundary springs included.
    pub stiffness: DMatrix<f64>,
    /// Indices of the free (not fixed) dofs, ascending.
    pub free: Vec<usize>,
}

impl FeModel {
    /// Assembles `M` and `K` of `beam` and applies `bc`.
    pub fn new(beam: &Beam, bc: &BoundaryConditions) -> Result<FeModel, String> {
        bc.validate()?;
        let ndof = beam.dofs();
        let h = beam.element_length();
        let ke = element::stiffness(&beam.material, &beam.section, h);
        let me = element::mass(&beam.material, &beam.section, h);
        let mut mass = DMatrix::zeros(ndof, ndof);
        let mut stiffness = DMatrix::zeros(ndof, ndof);
        for e in 0..beam.elements {
            let o = NODE_DOFS * e;
            for i in 0..element::ELEMENT_DOFS {
                for j in 0..element::ELEMENT_DOFS {
                    mass[(o + i, o + j)] += me[(i, j)];
                    stiffness[(o + i, o + j)] += ke[(i, j)];
                }
            }
        }
        let last = NODE_DOFS * beam.elements;
        let mut fixed = vec![false; ndof];
        for (o, end) in [(0, &bc.start), (last, &bc.end)] {
            for d in 0..NODE_DOFS {
                fixed[o + d] = end.fixed[d];
                if !end.fixed[d] {
                    stiffness[(o + d, o + d)] += end.springs[d];
                }
            }
        }
        let free = (0..ndof).filter(|&i| !fixed[i]).collect();
        Ok(FeModel {
            beam: *beam,
            bc: *bc,
            mass,
            stiffness,
            free,
        })
    }

    /// Number of dofs of the full (unconstrained) vector.
    pub fn dofs(&self) -> usize {
        self.beam.dofs()
    }

    /// `A` restricted to the free dofs (rows and columns).
    pub fn reduce_matrix(&self, a: &DMatrix<f64>) -> DMatrix<f64> {
        let f = &self.free;
        DMatrix::from_fn(f.len(), f.len(), |i, j| a[(f[i], f[j])])
    }

    /// `v` restricted to the free dofs.
    pub fn reduce_vector(&self, v: &DVector<f64>) -> DVector<f64> {
        DVector::from_fn(self.free.len(), |i, _| v[self.free[i]])
    }

    /// A free-dof vector expanded to all dofs (zeros at the fixed dofs).
    pub fn expand_vector(&self, v: &DVector<f64>) -> DVector<f64> {
        let mut full = DVector::zeros(self.dofs());
        for (i, &g) in self.free.iter().enumerate() {
            full[g] = v[i];
        }
        full
    }

    /// The six rigid-body displacement fields as columns (all dofs): the
    /// translations along x, y, z and the small rotations about x, y, z
    /// about the origin (`uz = -x, ry = 1` for y; `uy = x, rz = 1` for z).
    /// `K` of the unconstrained beam annihilates them.
    pub fn rigid_body_vectors(&self) -> DMatrix<f64> {
        let h = self.beam.element_length();
        let mut r = DMatrix::zeros(self.dofs(), 6);
        for node in 0..self.beam.nodes() {
            let x = node as f64 * h;
            let o = NODE_DOFS * node;
            r[(o + UX, 0)] = 1.0;
            r[(o + UY, 1)] = 1.0;
            r[(o + UZ, 2)] = 1.0;
            r[(o + RX, 3)] = 1.0;
            r[(o + UZ, 4)] = -x;
            r[(o + RY, 4)] = 1.0;
            r[(o + UY, 5)] = x;
            r[(o + RZ, 5)] = 1.0;
        }
        r
    }

    /// Number of rigid-body modes the boundary conditions leave: 6 minus the
    /// rank of the rigid-body vectors restricted to the fixed or sprung end
    /// dofs.
    pub fn rigid_body_count(&self) -> usize {
        let r = self.rigid_body_vectors();
        let last = NODE_DOFS * self.beam.elements;
        let mut rows = Vec::new();
        for (o, end) in [(0, &self.bc.start), (last, &self.bc.end)] {
            for d in 0..NODE_DOFS {
                if end.restrains(d) {
                    rows.push(o + d);
                }
            }
        }
        if rows.is_empty() {
            return 6;
        }
        // Scale the rotation columns so that all columns are O(1).
        let l = self.beam.length;
        let c = DMatrix::from_fn(rows.len(), 6, |i, j| {
            let s = if j >= 4 { 1.0 / l.max(1.0) } else { 1.0 };
            r[(rows[i], j)] * s
        });
        let sv = c.singular_values();
        let max = sv.max();
        let rank = sv.iter().filter(|&&s| s > 1e-10 * max).count();
        6 - rank
    }

    /// Consistent load vector (all dofs) of a uniform distributed force
    /// `q` per unit length (N/m, local axes) over the whole beam.
    pub fn uniform_load(&self, q: [f64; 3]) -> DVector<f64> {
        let fe = element::uniform_load(q, self.beam.element_length());
        let mut f = DVector::zeros(self.dofs());
        for e in 0..self.beam.elements {
            for i in 0..element::ELEMENT_DOFS {
                f[NODE_DOFS * e + i] += fe[i];
            }
        }
        f
    }

    /// Static displacement (all dofs, zeros at fixed dofs) under the load
    /// `f` (all dofs; entries at fixed dofs are reactions and ignored):
    /// `K_ff u_f = f_f`. Fails if `K_ff` is not positive definite (rigid-body
    /// modes left, e.g. free-free).
    pub fn solve_static(&self, f: &DVector<f64>) -> Result<DVector<f64>, String> {
        let k = self.reduce_matrix(&self.stiffness);
        let chol = k.cholesky().ok_or_else(|| {
            "stiffness on the free dofs is not positive definite (rigid-body modes left)"
                .to_string()
        })?;
        Ok(self.expand_vector(&chol.solve(&self.reduce_vector(f))))
    }

    /// Global geometric stiffness (all dofs) for the axial force field
    /// `axial_force(x)` (N, tension positive, `x` along the beam), integrated
    /// per element by 5-point Gauss quadrature (exact for polynomial `N(x)`
    /// up to degree 5).
    pub fn geometric_stiffness(&self, axial_force: impl Fn(f64) -> f64) -> DMatrix<f64> {
        let n = self.dofs();
        let h = self.beam.element_length();
        let mut kg = DMatrix::zeros(n, n);
        for e in 0..self.beam.elements {
            let x0 = e as f64 * h;
            let ke = element::geometric_stiffness_varying(h, |xi| axial_force(x0 + xi * h));
            let o = NODE_DOFS * e;
            for i in 0..element::ELEMENT_DOFS {
                for j in 0..element::ELEMENT_DOFS {
                    kg[(o + i, o + j)] += ke[(i, j)];
                }
            }
        }
        kg
    }

    /// Critical loads (N) of a uniform axial compression `P`, lowest first:
    /// the `count` smallest positive `P` with `det(K - P Kg1) = 0` on the free
    /// dofs, `Kg1` the geometric stiffness of a unit tension. Needs a
    /// positive definite `K_ff`.
    pub fn buckling_loads(&self, count: usize) -> Result<Vec<f64>, String> {
        let k = self.reduce_matrix(&self.stiffness);
        let kg = self.reduce_matrix(&self.geometric_stiffness(|_| 1.0));
        // K phi = P Kg phi  <=>  (L^-1 Kg L^-T) y = (1/P) y with K = L L^T.
        let mu = modal::generalized_eigenvalues(&kg, &k).ok_or_else(|| {
            "stiffness on the free dofs is not positive definite (rigid-body modes left)"
                .to_string()
        })?;
        let mut loads: Vec<f64> = mu
            .iter()
            .filter(|&&m| m > 1e-12 * mu.amax())
            .map(|&m| 1.0 / m)
            .collect();
        loads.sort_by(f64::total_cmp);
        loads.truncate(count);
        Ok(loads)
    }

    /// All elastic modes (rigid-body modes dropped), lowest first.
    pub fn modes(&self) -> Result<ModalBasis, String> {
        modal::solve(self)
    }

    /// The elastic modes kept by `selection`.
    pub fn modes_selected(&self, selection: ModeSelection) -> Result<ModalBasis, String> {
        Ok(modal::solve(self)?.select(selection))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn material() -> Material {
        Material::new(2.07e11, 0.33, 2740.0).unwrap()
    }

    #[test]
    fn validation_messages() {
        assert!(Material::new(-1.0, 0.3, 1.0).unwrap_err().contains("Young"));
        assert!(Material::new(1.0, 0.5, 1.0)
            .unwrap_err()
            .contains("Poisson"));
        assert!(Material::new(1.0, 0.3, 0.0)
            .unwrap_err()
            .contains("density"));
        assert!(Material::with_shear_modulus(1.0, f64::NAN, 1.0).is_err());
        assert!(Section::circle(0.0).unwrap_err().contains("radius"));
        assert!(Section::tube(0.01, 0.02).unwrap_err().contains("inner"));
        assert!(Section::tube(0.01, 0.01).is_err());
        assert!(Section::tube(0.01, -0.001).is_err());
        assert!(Section::general(1.0, 1.0, 1.0, 0.0, 1.0).is_err());
        let s = Section::circle(0.01).unwrap();
        assert!(Beam::new(0.0, material(), s, 4).is_err());
        assert!(Beam::new(1.0, material(), s, 0)
            .unwrap_err()
            .contains("element"));
        let beam = Beam::new(1.0, material(), s, 4).unwrap();
        let bc = BoundaryConditions::pinned_pinned_elastic(-1.0, 0.0);
        assert!(FeModel::new(&beam, &bc).unwrap_err().contains("spring"));
    }

    #[test]
    fn section_properties() {
        let pi = std::f64::consts::PI;
        let c = Section::circle(0.02).unwrap();
        assert!((c.area - pi * 4e-4).abs() < 1e-15);
        assert!((c.iz - pi * 1.6e-7 / 4.0).abs() < 1e-20);
        assert_eq!(c.polar, c.iy + c.iz);
        let t = Section::tube(0.02, 0.01).unwrap();
        assert!((t.area - pi * 3e-4).abs() < 1e-15);
        assert!((t.polar - pi * (1.6e-7 - 1e-8) / 2.0).abs() < 1e-20);
        let a = Section::circle_with_area(c.area).unwrap();
        assert!((a.iz - c.iz).abs() < 1e-12 * c.iz);
        let m = material();
        assert!((m.shear_modulus - 2.07e11 / 2.66).abs() < 1.0);
    }

    #[test]
    fn rigid_body_vectors_are_stress_free_and_counted() {
        let beam = Beam::new(0.8, material(), Section::circle(0.0148).unwrap(), 5).unwrap();
        let free = FeModel::new(&beam, &BoundaryConditions::free_free()).unwrap();
        let r = free.rigid_body_vectors();
        let kr = &free.stiffness * &r;
        assert!(kr.amax() < 1e-9 * free.stiffness.amax(), "{}", kr.amax());
        assert_eq!(free.rigid_body_count(), 6);
        for bc in [
            BoundaryConditions::clamped_free(),
            BoundaryConditions::pinned_pinned(),
            BoundaryConditions::pinned_pinned_elastic(10.0, 20.0),
            BoundaryConditions::clamped_clamped(),
        ] {
            let model = FeModel::new(&beam, &bc).unwrap();
            assert_eq!(model.rigid_body_count(), 0);
            // No rigid-body mode left: K on the free dofs is positive definite.
            assert!(model.reduce_matrix(&model.stiffness).cholesky().is_some());
        }
        // Pinned at the start only: the rotations about y and z are left.
        let bc = BoundaryConditions {
            start: EndCondition::fixing(&[UX, UY, UZ, RX]),
            end: EndCondition::free(),
        };
        assert_eq!(FeModel::new(&beam, &bc).unwrap().rigid_body_count(), 2);
    }

    #[test]
    fn joint_stiffness_of_the_spec_member() {
        let j = shaft_joint_stiffness(&material(), 0.07, 0.04).unwrap();
        let a: f64 = 0.07 / (2740.0 * 0.04);
        let ip = a * a / (2.0 * std::f64::consts::PI);
        assert!((j.torsional - 2.07e11 / 2.66 * ip / 0.04).abs() < 1e-9 * j.torsional);
        assert!((j.bending - 2.07e11 * ip / 2.0 / 0.04).abs() < 1e-9 * j.bending);
        assert!(
            j.torsional > 1.2e5 && j.torsional < 1.3e5,
            "{}",
            j.torsional
        );
        assert!(shaft_joint_stiffness(&material(), 0.0, 0.04).is_err());
    }

    #[test]
    fn static_solve_rejects_free_free() {
        let beam = Beam::new(1.0, material(), Section::circle(0.01).unwrap(), 3).unwrap();
        let model = FeModel::new(&beam, &BoundaryConditions::free_free()).unwrap();
        let f = model.uniform_load([0.0, 1.0, 0.0]);
        assert!(model.solve_static(&f).is_err());
        assert!(model.buckling_loads(1).is_err());
    }
}
