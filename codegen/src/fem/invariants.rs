//! FFRF shape integrals ("inertia invariants") of a beam projected on a
//! modal basis, and the kinetic energy assembled from them (formulas in the
//! [module docs](super)).

use nalgebra::{DMatrix, DVector};

use super::element::{translation_shape, ELEMENT_DOFS, GAUSS4};
use super::modal::{ModalBasis, Station};
use super::{FeModel, NODE_DOFS};

/// The shape integrals of one flexible body for `k` kept modes; indices
/// `a, b` run over the frame axes x, y, z.
#[derive(Debug, Clone, PartialEq)]
pub struct Invariants {
    /// `m = int rho A dx`.
    pub mass: f64,
    /// `S0 = int rho A u0 dx`.
    pub s0: [f64; 3],
    /// `S1 = int rho A N Phi dx`, 3 x k.
    pub s1: DMatrix<f64>,
    /// `I0_ab = int rho A u0_a u0_b dx`.
    pub i0: [[f64; 3]; 3],
    /// `I1[a][b] = int rho A u0_a (N_b Phi) dx`, k-vectors.
    pub i1: [[DVector<f64>; 3]; 3],
    /// `I2[a][b] = int rho A (N_a Phi)^T (N_b Phi) dx`, k x k.
    pub i2: [[DMatrix<f64>; 3]; 3],
    /// `Mff = Phi^T M Phi` (identity up to round-off).
    pub mff: DMatrix<f64>,
    /// `Kff = Phi^T K Phi` (`diag(w^2)` up to round-off).
    pub kff: DMatrix<f64>,
    /// Circular frequencies of the modes (rad/s).
    pub omega: Vec<f64>,
    /// Elastic translation and rotation of the start node (`x = 0`).
    pub start: Station,
    /// Elastic translation and rotation of the end node (`x = L`).
    pub end: Station,
}

impl Invariants {
    /// The invariants of `model`'s beam for the modes in `basis`.
    ///
    /// # Panics
    ///
    /// If `basis` does not come from `model`'s mesh (wrong number of dofs).
    pub fn new(model: &FeModel, basis: &ModalBasis) -> Invariants {
        assert_eq!(
            basis.shapes.nrows(),
            model.dofs(),
            "modal basis of another mesh"
        );
        let k = basis.len();
        let beam = &model.beam;
        let h = beam.element_length();
        let rho_a = beam.mass_per_length();
        let mut mass = 0.0;
        let mut s0 = [0.0; 3];
        let mut s1 = DMatrix::zeros(3, k);
        let mut i0 = [[0.0; 3]; 3];
        let mut i1: [[DVector<f64>; 3]; 3] =
            std::array::from_fn(|_| std::array::from_fn(|_| DVector::zeros(k)));
        let mut i2: [[DMatrix<f64>; 3]; 3] =
            std::array::from_fn(|_| std::array::from_fn(|_| DMatrix::zeros(k, k)));
        let mut p = DMatrix::zeros(3, k);
        for e in 0..beam.elements {
            let phi_e = basis.shapes.rows(NODE_DOFS * e, ELEMENT_DOFS);
            for &(xi, w) in GAUSS4.iter() {
                let x = (e as f64 + xi) * h;
                let f = w * h * rho_a;
                let u0 = [x, 0.0, 0.0];
                // p = N(x) Phi_e: row a is N_a Phi.
                let n = translation_shape(xi, h);
                p.fill(0.0);
                for a in 0..3 {
                    for i in 0..ELEMENT_DOFS {
                        let nai = n[(a, i)];
                        if nai != 0.0 {
                            for j in 0..k {
                                p[(a, j)] += nai * phi_e[(i, j)];
                            }
                        }
                    }
                }
                mass += f;
                for a in 0..3 {
                    s0[a] += f * u0[a];
                    for j in 0..k {
                        s1[(a, j)] += f * p[(a, j)];
                    }
                    for b in 0..3 {
                        i0[a][b] += f * u0[a] * u0[b];
                        if u0[a] != 0.0 {
                            for j in 0..k {
                                i1[a][b][j] += f * u0[a] * p[(b, j)];
                            }
                        }
                        if b > a {
                            let ia = &mut i2[a][b];
                            for i in 0..k {
                                let pa = f * p[(a, i)];
                                for j in 0..k {
                                    ia[(i, j)] += pa * p[(b, j)];
                                }
                            }
                        } else if b == a {
                            // Symmetric: the upper triangle, mirrored below.
                            let ia = &mut i2[a][a];
                            for i in 0..k {
                                let pa = f * p[(a, i)];
                                for j in i..k {
                                    ia[(i, j)] += pa * p[(a, j)];
                                }
                            }
                        }
                    }
                }
            }
        }
        for a in 0..3 {
            for b in 0..a {
                i2[a][b] = i2[b][a].transpose();
            }
            let ia = &mut i2[a][a];
            for i in 0..k {
                for j in 0..i {
                    ia[(i, j)] = ia[(j, i)];
                }
            }
        }
        let l = beam.length;
        Invariants {
            mass,
            s0,
            s1,
            i0,
            i1,
            i2,
            mff: basis.project(&model.mass),
            kff: basis.project(&model.stiffness),
            omega: basis.omega.clone(),
            start: basis.station(0.0).expect("x = 0 is on the beam"),
            end: basis.station(l).expect("x = L is on the beam"),
        }
    }

    /// Number of modes `k`.
    pub fn modes(&self) -> usize {
        self.omega.len()
    }

    /// First moment of mass `c(eta) = S0 + S1 eta = int rho A u dx`.
    pub fn first_moment(&self, eta: &[f64]) -> [f64; 3] {
        self.check_len(eta);
        std::array::from_fn(|a| {
            self.s0[a]
                + (0..eta.len())
                    .map(|j| self.s1[(a, j)] * eta[j])
                    .sum::<f64>()
        })
    }

    /// Second moments `J_ab(eta) = int rho A u_a u_b dx`.
    pub fn second_moment(&self, eta: &[f64]) -> [[f64; 3]; 3] {
        self.check_len(eta);
        let e = DVector::from_column_slice(eta);
        std::array::from_fn(|a| {
            std::array::from_fn(|b| {
                self.i0[a][b]
                    + self.i1[a][b].dot(&e)
                    + self.i1[b][a].dot(&e)
                    + (e.transpose() * &self.i2[a][b] * &e)[0]
            })
        })
    }

    /// Inertia tensor about the frame origin, `Theta = trace(J) 1 - J`.
    pub fn inertia_tensor(&self, eta: &[f64]) -> [[f64; 3]; 3] {
        let j = self.second_moment(eta);
        let tr = j[0][0] + j[1][1] + j[2][2];
        std::array::from_fn(|a| std::array::from_fn(|b| if a == b { tr } else { 0.0 } - j[a][b]))
    }

    /// `h = int rho A u x u_f_dot dx`, the angular momentum of the elastic
    /// motion about the frame origin (per the frame's axes).
    pub fn elastic_angular_momentum(&self, eta: &[f64], eta_dot: &[f64]) -> [f64; 3] {
        self.check_len(eta);
        self.check_len(eta_dot);
        let e = DVector::from_column_slice(eta);
        let ed = DVector::from_column_slice(eta_dot);
        // g[b][c] = int rho A u_b u_f_dot_c dx.
        let g =
            |b: usize, c: usize| self.i1[b][c].dot(&ed) + (e.transpose() * &self.i2[b][c] * &ed)[0];
        [g(1, 2) - g(2, 1), g(2, 0) - g(0, 2), g(0, 1) - g(1, 0)]
    }

    fn check_len(&self, v: &[f64]) {
        assert_eq!(v.len(), self.modes(), "one modal coordinate per mode");
    }
}

#[cfg(test)]
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Kinetic energy of the flexible body, `T = 1/2 int rho A |V + w x u +
/// u_f_dot|^2 dx + 1/2 int rho Ip rx_dot^2 dx`, evaluated from the
/// invariants: `v` is the velocity of the frame origin and `w` the angular
/// velocity of the frame, both in frame axes; `eta`, `eta_dot` the modal
/// coordinates and their rates.
///
/// # Panics
///
/// If `eta` or `eta_dot` does not have one entry per mode.
///
/// The generator builds these energies symbolically; this numerical
/// evaluation is the reference the tests compare them with.
#[cfg(test)]
pub fn kinetic_energy(
    inv: &Invariants,
    v: [f64; 3],
    w: [f64; 3],
    eta: &[f64],
    eta_dot: &[f64],
) -> f64 {
    let c = inv.first_moment(eta);
    let theta = inv.inertia_tensor(eta);
    let h = inv.elastic_angular_momentum(eta, eta_dot);
    let ed = DVector::from_column_slice(eta_dot);
    let s1_ed = &inv.s1 * &ed;
    let mut rot = 0.0;
    for a in 0..3 {
        for b in 0..3 {
            rot += w[a] * theta[a][b] * w[b];
        }
    }
    0.5 * inv.mass * dot(v, v)
        + dot(v, cross(w, c))
        + 0.5 * rot
        + dot(v, [s1_ed[0], s1_ed[1], s1_ed[2]])
        + dot(w, h)
        + 0.5 * (ed.transpose() * &inv.mff * &ed)[0]
}

#[cfg(test)]
mod tests {
    use super::super::{Beam, BoundaryConditions, Material, ModeSelection, Section, RX};
    use super::*;

    fn model(bc: BoundaryConditions, n: usize) -> FeModel {
        let m = Material::new(2.07e11, 0.33, 2740.0).unwrap();
        let beam = Beam::new(0.8, m, Section::circle(0.0148).unwrap(), n).unwrap();
        FeModel::new(&beam, &bc).unwrap()
    }

    #[test]
    fn rigid_parts_are_the_rod_closed_forms() {
        let model = model(BoundaryConditions::pinned_pinned(), 7);
        let basis = model.modes_selected(ModeSelection::First(5)).unwrap();
        let inv = Invariants::new(&model, &basis);
        let (rho_a, l) = (model.beam.mass_per_length(), 0.8);
        let m = rho_a * l;
        assert!((inv.mass - m).abs() < 1e-12 * m);
        assert!((inv.s0[0] - m * l / 2.0).abs() < 1e-12 * m);
        assert_eq!((inv.s0[1], inv.s0[2]), (0.0, 0.0));
        assert!((inv.i0[0][0] - m * l * l / 3.0).abs() < 1e-12 * m);
        // A rod spinning about z through its end: 1/2 (m l^2 / 3) w^2.
        let z = [0.0; 5];
        let t = kinetic_energy(&inv, [0.0; 3], [0.0, 0.0, 2.0], &z, &z);
        assert!((t - 0.5 * m * l * l / 3.0 * 4.0).abs() < 1e-12 * t);
        // Translation plus spin: 1/2 m v^2 + v.(w x S0) + ...
        let t = kinetic_energy(&inv, [0.0, 3.0, 0.0], [0.0, 0.0, 2.0], &z, &z);
        let exact = 0.5 * m * 9.0 + 3.0 * 2.0 * m * l / 2.0 + 0.5 * m * l * l / 3.0 * 4.0;
        assert!((t - exact).abs() < 1e-12 * t);
    }

    #[test]
    fn modal_mass_is_the_translational_plus_torsional_integral() {
        let model = model(BoundaryConditions::clamped_free(), 6);
        let basis = model.modes_selected(ModeSelection::First(12)).unwrap();
        let inv = Invariants::new(&model, &basis);
        // Torsional part: Phi^T M_rx Phi with M restricted to the rx dofs.
        let mut m_rx = DMatrix::zeros(model.dofs(), model.dofs());
        for i in (RX..model.dofs()).step_by(NODE_DOFS) {
            for j in (RX..model.dofs()).step_by(NODE_DOFS) {
                m_rx[(i, j)] = model.mass[(i, j)];
            }
        }
        let sum = &inv.i2[0][0] + &inv.i2[1][1] + &inv.i2[2][2] + basis.project(&m_rx);
        let diff = (sum - &inv.mff).amax();
        assert!(diff < 1e-10, "{diff}");
        assert!((&inv.mff - DMatrix::identity(12, 12)).amax() < 1e-10);
        for a in 0..3 {
            for b in 0..3 {
                assert_eq!(inv.i2[a][b], inv.i2[b][a].transpose());
            }
        }
    }

    #[test]
    fn free_free_modes_satisfy_the_mean_axis_conditions() {
        let model = model(BoundaryConditions::free_free(), 10);
        let basis = model.modes_selected(ModeSelection::First(10)).unwrap();
        assert_eq!(basis.rigid_body_modes, 6);
        let inv = Invariants::new(&model, &basis);
        let scale = inv.mass.sqrt();
        assert!(inv.s1.amax() < 1e-9 * scale, "S1 = {}", inv.s1.amax());
        // int rho A u0 x u_f = 0: I1[x][y] = I1[x][z] = 0 (u0 only along x).
        assert!(inv.i1[0][1].amax() < 1e-9 * scale);
        assert!(inv.i1[0][2].amax() < 1e-9 * scale);
    }
}
