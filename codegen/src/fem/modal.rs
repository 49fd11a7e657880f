//! Normal modes of a constrained beam: `K phi = w^2 M phi` on the free dofs,
//! mass-normalised, sorted, truncated, expanded to all dofs.

use nalgebra::{DMatrix, DVector, SymmetricEigen};

use super::element::{rotation_shape, translation_shape, ELEMENT_DOFS};
use super::{Beam, FeModel, NODE_DOFS, RX, RY, RZ, UX, UY, UZ};

/// Which motion a mode involves (from its nonzero dofs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ModeKind {
    /// Only `ux`.
    Axial,
    /// Only `rx`.
    Torsion,
    /// Only `uy`, `rz`: bending in the x-y plane (deflection along `y`).
    BendingXY,
    /// Only `uz`, `ry`: bending in the x-z plane (deflection along `z`).
    BendingXZ,
    /// Any other combination.
    Coupled,
}

/// Which modes to keep.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ModeSelection {
    /// Every elastic mode of the mesh.
    All,
    /// The `k` lowest.
    First(usize),
    /// Those with frequency strictly below the cutoff (Hz).
    BelowHz(f64),
}

impl Default for ModeSelection {
    /// `First(6)`: the paper keeps six modes per flexible part.
    fn default() -> ModeSelection {
        ModeSelection::First(6)
    }
}

/// Elastic displacement of one point of the centre line in terms of the
/// modal coordinates: `u_f = translation eta`, small rotation of the section
/// `= rotation eta` (rows x, y, z; `k` columns).
#[derive(Debug, Clone, PartialEq)]
pub struct Station {
    /// Position along the beam (m).
    pub x: f64,
    /// 3 x k: rows `ux`, `uy`, `uz`.
    pub translation: DMatrix<f64>,
    /// 3 x k: rows `rx`, `ry`, `rz`.
    pub rotation: DMatrix<f64>,
}

/// A set of mass-normalised elastic modes of a beam.
#[derive(Debug, Clone, PartialEq)]
pub struct ModalBasis {
    /// The beam they belong to.
    pub beam: Beam,
    /// Circular frequencies `w_j` (rad/s), ascending.
    pub omega: Vec<f64>,
    /// Mode shapes as columns over all `6 (n + 1)` dofs (zeros at fixed
    /// dofs), `phi_j^T M phi_j = 1`, largest entry positive.
    pub shapes: DMatrix<f64>,
    /// What each mode involves.
    pub kinds: Vec<ModeKind>,
    /// Rigid-body modes of the boundary conditions that were dropped.
    pub rigid_body_modes: usize,
}

impl ModalBasis {
    /// Number of modes `k`.
    pub fn len(&self) -> usize {
        self.omega.len()
    }

    /// Whether no mode is kept.
    pub fn is_empty(&self) -> bool {
        self.omega.is_empty()
    }

    /// Frequencies in Hz.
    pub fn frequencies_hz(&self) -> Vec<f64> {
        self.omega
            .iter()
            .map(|w| w / (2.0 * std::f64::consts::PI))
            .collect()
    }

    fn subset(&self, keep: &[usize]) -> ModalBasis {
        ModalBasis {
            beam: self.beam,
            omega: keep.iter().map(|&j| self.omega[j]).collect(),
            shapes: self.shapes.select_columns(keep),
            kinds: keep.iter().map(|&j| self.kinds[j]).collect(),
            rigid_body_modes: self.rigid_body_modes,
        }
    }

    /// The modes kept by `selection` (order preserved). Note that `First(k)`
    /// may split a pair of equal frequencies (round sections); select by
    /// kind first, or use a cutoff, to keep both planes.
    pub fn select(&self, selection: ModeSelection) -> ModalBasis {
        let keep: Vec<usize> = match selection {
            ModeSelection::All => (0..self.len()).collect(),
            ModeSelection::First(k) => (0..k.min(self.len())).collect(),
            ModeSelection::BelowHz(f) => (0..self.len())
                .filter(|&j| self.omega[j] / (2.0 * std::f64::consts::PI) < f)
                .collect(),
        };
        self.subset(&keep)
    }

    /// Only the modes whose kind is in `kinds` (order preserved).
    pub fn retain_kinds(&self, kinds: &[ModeKind]) -> ModalBasis {
        let keep: Vec<usize> = (0..self.len())
            .filter(|&j| kinds.contains(&self.kinds[j]))
            .collect();
        self.subset(&keep)
    }

    /// `Phi^T A Phi` (k x k) for an all-dofs matrix `A` (mass, stiffness,
    /// geometric stiffness).
    pub fn project(&self, a: &DMatrix<f64>) -> DMatrix<f64> {
        self.shapes.transpose() * a * &self.shapes
    }

    /// Modal superposition of the static response to the load `f` (all
    /// dofs): `sum_j phi_j (phi_j^T f) / w_j^2`.
    pub fn static_response(&self, f: &DVector<f64>) -> DVector<f64> {
        let mut q = self.shapes.transpose() * f;
        for j in 0..self.len() {
            q[j] /= self.omega[j] * self.omega[j];
        }
        &self.shapes * q
    }

    /// The elastic translation and small rotation at `x` along the beam
    /// (`0 <= x <= L`), interpolated with the element shape functions (the
    /// rows of `Phi` at a node).
    pub fn station(&self, x: f64) -> Result<Station, String> {
        let l = self.beam.length;
        if !(x.is_finite() && x >= -1e-12 * l && x <= l * (1.0 + 1e-12)) {
            return Err(format!("station x = {x} is outside the beam [0, {l}]"));
        }
        let h = self.beam.element_length();
        let e = ((x / h).floor().max(0.0) as usize).min(self.beam.elements - 1);
        let xi = ((x - e as f64 * h) / h).clamp(0.0, 1.0);
        let phi_e = self.shapes.rows(NODE_DOFS * e, ELEMENT_DOFS);
        let n = translation_shape(xi, h);
        let r = rotation_shape(xi, h);
        let k = self.len();
        let mut translation = DMatrix::zeros(3, k);
        let mut rotation = DMatrix::zeros(3, k);
        for a in 0..3 {
            for j in 0..k {
                for i in 0..ELEMENT_DOFS {
                    translation[(a, j)] += n[(a, i)] * phi_e[(i, j)];
                    rotation[(a, j)] += r[(a, i)] * phi_e[(i, j)];
                }
            }
        }
        Ok(Station {
            x,
            translation,
            rotation,
        })
    }
}

/// Eigenpairs of `A y = lambda B y` for symmetric `A` and symmetric
/// positive definite `B`, `Y^T B Y = I`, unsorted; `None` if `B` is not
/// positive definite.
pub fn generalized_eigen(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
) -> Option<(DVector<f64>, DMatrix<f64>)> {
    let l = b.clone().cholesky()?.unpack();
    let c = transformed(a, &l)?;
    let eig = SymmetricEigen::new(c);
    let phi = l.transpose().solve_upper_triangular(&eig.eigenvectors)?;
    Some((eig.eigenvalues, phi))
}

/// Eigenvalues of `A y = lambda B y` (see [`generalized_eigen`]).
pub fn generalized_eigenvalues(a: &DMatrix<f64>, b: &DMatrix<f64>) -> Option<DVector<f64>> {
    let l = b.clone().cholesky()?.unpack();
    Some(transformed(a, &l)?.symmetric_eigenvalues())
}

/// `L^-1 A L^-T`, symmetrised.
fn transformed(a: &DMatrix<f64>, l: &DMatrix<f64>) -> Option<DMatrix<f64>> {
    let x = l.solve_lower_triangular(a)?; // L^-1 A
    let c = l.solve_lower_triangular(&x.transpose())?; // L^-1 (L^-1 A)^T = L^-1 A L^-T
    Some((&c + c.transpose()) * 0.5)
}

/// Connected components of the coupling pattern of `K + M` on the free
/// dofs, each ascending, ordered by their first dof.
fn components(k: &DMatrix<f64>, m: &DMatrix<f64>) -> Vec<Vec<usize>> {
    let n = k.nrows();
    let mut parent: Vec<usize> = (0..n).collect();
    fn root(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for i in 0..n {
        for j in (i + 1)..n {
            if k[(i, j)] != 0.0 || m[(i, j)] != 0.0 {
                let (ri, rj) = (root(&mut parent, i), root(&mut parent, j));
                if ri != rj {
                    parent[ri.max(rj)] = ri.min(rj);
                }
            }
        }
    }
    let mut groups: Vec<Vec<usize>> = Vec::new();
    let mut slot = vec![usize::MAX; n];
    for i in 0..n {
        let r = root(&mut parent, i);
        if slot[r] == usize::MAX {
            slot[r] = groups.len();
            groups.push(Vec::new());
        }
        groups[slot[r]].push(i);
    }
    groups
}

fn classify(shape: &DVector<f64>) -> ModeKind {
    let max = shape.amax();
    let mut used = [false; NODE_DOFS];
    for (i, v) in shape.iter().enumerate() {
        if v.abs() > 1e-12 * max {
            used[i % NODE_DOFS] = true;
        }
    }
    let only = |dofs: &[usize]| (0..NODE_DOFS).all(|d| !used[d] || dofs.contains(&d));
    if only(&[UX]) {
        ModeKind::Axial
    } else if only(&[RX]) {
        ModeKind::Torsion
    } else if only(&[UY, RZ]) {
        ModeKind::BendingXY
    } else if only(&[UZ, RY]) {
        ModeKind::BendingXZ
    } else {
        ModeKind::Coupled
    }
}

struct Mode {
    lambda: f64,
    shape: DVector<f64>,
    kind: ModeKind,
    component: usize,
}

/// All elastic modes of `model` (see [`FeModel::modes`]).
pub(super) fn solve(model: &FeModel) -> Result<ModalBasis, String> {
    let free = &model.free;
    let kf = model.reduce_matrix(&model.stiffness);
    let mf = model.reduce_matrix(&model.mass);
    let rigid = model.rigid_body_count();
    let mut modes = Vec::with_capacity(free.len());
    for (c, dofs) in components(&kf, &mf).iter().enumerate() {
        let kc = DMatrix::from_fn(dofs.len(), dofs.len(), |i, j| kf[(dofs[i], dofs[j])]);
        let mc = DMatrix::from_fn(dofs.len(), dofs.len(), |i, j| mf[(dofs[i], dofs[j])]);
        if rigid == 0 && kc.clone().cholesky().is_none() {
            return Err(
                "the stiffness on the free dofs is not positive definite: the boundary \
                 conditions leave a mechanism"
                    .to_string(),
            );
        }
        let (_, phi) = generalized_eigen(&kc, &mc)
            .ok_or_else(|| "mass matrix on the free dofs is not positive definite".to_string())?;
        for j in 0..dofs.len() {
            let y = phi.column(j);
            // Rayleigh quotient: second-order accurate in the shape error.
            let lambda = (y.transpose() * &kc * y)[0] / (y.transpose() * &mc * y)[0];
            let mut shape = DVector::zeros(model.dofs());
            for (i, &d) in dofs.iter().enumerate() {
                shape[free[d]] = y[i];
            }
            modes.push(Mode {
                lambda,
                kind: classify(&shape),
                shape,
                component: c,
            });
        }
    }
    modes.sort_by(|a, b| a.lambda.total_cmp(&b.lambda));
    if rigid > modes.len() {
        return Err("fewer free dofs than rigid-body modes".to_string());
    }
    modes.drain(..rigid);
    // Equal frequencies (round sections): x-y plane first, then by block.
    let mut start = 0;
    while start < modes.len() {
        let mut end = start + 1;
        while end < modes.len()
            && modes[end].lambda - modes[end - 1].lambda <= 1e-9 * modes[end].lambda
        {
            end += 1;
        }
        modes[start..end].sort_by_key(|m| (m.kind, m.component));
        start = end;
    }
    let k = modes.len();
    let mut shapes = DMatrix::zeros(model.dofs(), k);
    let mut omega = Vec::with_capacity(k);
    let mut kinds = Vec::with_capacity(k);
    for (j, mode) in modes.into_iter().enumerate() {
        let max = mode.shape.amax();
        let lead = mode
            .shape
            .iter()
            .position(|v| v.abs() >= max * (1.0 - 1e-9))
            .unwrap_or(0);
        let sign = if mode.shape[lead] < 0.0 { -1.0 } else { 1.0 };
        shapes.set_column(j, &(mode.shape * sign));
        omega.push(mode.lambda.sqrt());
        kinds.push(mode.kind);
    }
    Ok(ModalBasis {
        beam: model.beam,
        omega,
        shapes,
        kinds,
        rigid_body_modes: rigid,
    })
}

#[cfg(test)]
mod tests {
    use super::super::{BoundaryConditions, Material, Section};
    use super::*;

    fn beam(n: usize) -> Beam {
        let m = Material::new(2.07e11, 0.33, 2740.0).unwrap();
        Beam::new(0.8, m, Section::circle(0.0148).unwrap(), n).unwrap()
    }

    #[test]
    fn modes_are_mass_normalised_and_sorted() {
        for bc in [
            BoundaryConditions::pinned_pinned(),
            BoundaryConditions::clamped_free(),
            BoundaryConditions::free_free(),
        ] {
            let model = FeModel::new(&beam(6), &bc).unwrap();
            let basis = model.modes().unwrap();
            assert_eq!(basis.len() + basis.rigid_body_modes, model.free.len());
            let mff = basis.project(&model.mass);
            let kff = basis.project(&model.stiffness);
            let k = basis.len();
            assert!((mff - DMatrix::identity(k, k)).amax() < 1e-10);
            let top = basis.omega[k - 1].powi(2);
            for i in 0..k {
                assert!((kff[(i, i)] - basis.omega[i].powi(2)).abs() < 1e-9 * top);
                for j in 0..k {
                    if i != j {
                        assert!(kff[(i, j)].abs() < 1e-9 * top);
                    }
                }
            }
            // Ascending, up to the ordering of equal pairs.
            assert!(basis.omega.windows(2).all(|w| w[0] <= w[1] * (1.0 + 1e-9)));
            assert!(basis.kinds.iter().all(|&k| k != ModeKind::Coupled));
            // Zeros at the fixed dofs.
            for d in 0..model.dofs() {
                if !model.free.contains(&d) {
                    assert_eq!(basis.shapes.row(d).amax(), 0.0);
                }
            }
        }
    }

    #[test]
    fn selection_and_kinds() {
        let model = FeModel::new(&beam(8), &BoundaryConditions::pinned_pinned()).unwrap();
        let all = model.modes().unwrap();
        assert_eq!(all.select(ModeSelection::default()).len(), 6);
        assert_eq!(all.select(ModeSelection::First(3)).len(), 3);
        assert_eq!(all.select(ModeSelection::First(10_000)).len(), all.len());
        // Round section: equal pairs, x-y plane first.
        assert_eq!(all.kinds[0], ModeKind::BendingXY);
        assert_eq!(all.kinds[1], ModeKind::BendingXZ);
        assert!((all.omega[0] - all.omega[1]).abs() < 1e-9 * all.omega[0]);
        let below = all.select(ModeSelection::BelowHz(1000.0));
        assert!(below.frequencies_hz().iter().all(|&f| f < 1000.0));
        assert_eq!(below.len(), 4);
        let xy = all.retain_kinds(&[ModeKind::BendingXY]);
        assert!(xy.kinds.iter().all(|&k| k == ModeKind::BendingXY));
        assert!(all.kinds.contains(&ModeKind::Axial));
        assert!(all.kinds.contains(&ModeKind::Torsion));
    }

    #[test]
    fn stations_are_the_nodal_rows() {
        let model = FeModel::new(&beam(5), &BoundaryConditions::clamped_free()).unwrap();
        let basis = model.modes_selected(ModeSelection::First(8)).unwrap();
        let l = model.beam.length;
        let end = basis.station(l).unwrap();
        let o = NODE_DOFS * 5;
        for j in 0..basis.len() {
            for a in 0..3 {
                assert_eq!(end.translation[(a, j)], basis.shapes[(o + a, j)]);
                assert!((end.rotation[(a, j)] - basis.shapes[(o + 3 + a, j)]).abs() < 1e-12);
            }
        }
        let start = basis.station(0.0).unwrap();
        assert!(start.translation.amax() == 0.0 && start.rotation.amax() < 1e-12);
        assert!(basis.station(l * 1.01).is_err());
        assert!(basis.station(-0.1).is_err());
    }

    #[test]
    fn components_split_a_straight_beam_in_four() {
        let model = FeModel::new(&beam(4), &BoundaryConditions::clamped_free()).unwrap();
        let kf = model.reduce_matrix(&model.stiffness);
        let mf = model.reduce_matrix(&model.mass);
        let comps = components(&kf, &mf);
        assert_eq!(comps.len(), 4);
        assert_eq!(comps.iter().map(Vec::len).sum::<usize>(), model.free.len());
    }
}
