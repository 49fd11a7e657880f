//! The 12-dof 3D Euler-Bernoulli beam element in its local frame (formulas in
//! the [module docs](super)), its shape functions and Gauss rules.
//!
//! Element dofs: node `a` (`x = 0`) dofs `0..6`, node `b` (`x = h`) dofs
//! `6..12`, each in the order ux, uy, uz, rx, ry, rz.

use nalgebra::{SMatrix, SVector};

use super::{Material, Section, NODE_DOFS, RX, RY, RZ, UX, UY, UZ};

/// Dofs of one element.
pub const ELEMENT_DOFS: usize = 12;

/// A 12 x 12 element matrix.
pub type ElementMatrix = SMatrix<f64, 12, 12>;
/// A 12-vector of element dofs.
pub type ElementVector = SVector<f64, 12>;

/// Bending plane x-y: `(dof, sign)` of `(v_a, theta_a, v_b, theta_b)` with
/// `theta = dv/dx` (`rz = +dv/dx`).
pub const PLANE_XY: [(usize, f64); 4] = [
    (UY, 1.0),
    (RZ, 1.0),
    (NODE_DOFS + UY, 1.0),
    (NODE_DOFS + RZ, 1.0),
];
/// Bending plane x-z: `(dof, sign)` of `(w_a, theta_a, w_b, theta_b)` with
/// `theta = dw/dx` (`ry = -dw/dx`).
pub const PLANE_XZ: [(usize, f64); 4] = [
    (UZ, 1.0),
    (RY, -1.0),
    (NODE_DOFS + UZ, 1.0),
    (NODE_DOFS + RY, -1.0),
];

/// Gauss-Legendre rule with 4 points on `[0, 1]`: `(xi, weight)`, exact for
/// polynomials of degree <= 7.
pub const GAUSS4: [(f64, f64); 4] = [
    (0.069_431_844_202_973_71, 0.173_927_422_568_726_9),
    (0.330_009_478_207_571_9, 0.326_072_577_431_273_1),
    (0.669_990_521_792_428_1, 0.326_072_577_431_273_1),
    (0.930_568_155_797_026_3, 0.173_927_422_568_726_9),
];

/// Gauss-Legendre rule with 5 points on `[0, 1]`: `(xi, weight)`, exact for
/// polynomials of degree <= 9.
pub const GAUSS5: [(f64, f64); 5] = [
    (0.046_910_077_030_668, 0.118_463_442_528_094_5),
    (0.230_765_344_947_158_5, 0.239_314_335_249_683_2),
    (0.5, 0.284_444_444_444_444_4),
    (0.769_234_655_052_841_5, 0.239_314_335_249_683_2),
    (0.953_089_922_969_332, 0.118_463_442_528_094_5),
];

/// Cubic Hermite functions `[H1, H2, H3, H4]` at `xi = x / h` for
/// `(u_a, theta_a, u_b, theta_b)`, `theta = du/dx`.
pub fn hermite(xi: f64, h: f64) -> [f64; 4] {
    let x2 = xi * xi;
    let x3 = x2 * xi;
    [
        1.0 - 3.0 * x2 + 2.0 * x3,
        h * (xi - 2.0 * x2 + x3),
        3.0 * x2 - 2.0 * x3,
        h * (x3 - x2),
    ]
}

/// `d/dx` of [`hermite`].
pub fn hermite_slope(xi: f64, h: f64) -> [f64; 4] {
    let x2 = xi * xi;
    [
        (-6.0 * xi + 6.0 * x2) / h,
        1.0 - 4.0 * xi + 3.0 * x2,
        (6.0 * xi - 6.0 * x2) / h,
        3.0 * x2 - 2.0 * xi,
    ]
}

/// Centre-line translation interpolation at `xi`: row `a` gives `u_a`
/// (a = x, y, z) from the 12 element dofs.
pub fn translation_shape(xi: f64, h: f64) -> SMatrix<f64, 3, 12> {
    let mut n = SMatrix::<f64, 3, 12>::zeros();
    n[(0, UX)] = 1.0 - xi;
    n[(0, NODE_DOFS + UX)] = xi;
    let hm = hermite(xi, h);
    for (row, plane) in [(1, &PLANE_XY), (2, &PLANE_XZ)] {
        for (k, &(dof, sign)) in plane.iter().enumerate() {
            n[(row, dof)] = sign * hm[k];
        }
    }
    n
}

/// Small-rotation interpolation at `xi`: row 0 the twist `rx` (linear),
/// row 1 `ry = -dw/dx`, row 2 `rz = dv/dx`; equal to the nodal rotations at
/// the nodes.
pub fn rotation_shape(xi: f64, h: f64) -> SMatrix<f64, 3, 12> {
    let mut n = SMatrix::<f64, 3, 12>::zeros();
    n[(0, RX)] = 1.0 - xi;
    n[(0, NODE_DOFS + RX)] = xi;
    let d = hermite_slope(xi, h);
    for (k, &(dof, sign)) in PLANE_XZ.iter().enumerate() {
        n[(1, dof)] = -sign * d[k];
    }
    for (k, &(dof, sign)) in PLANE_XY.iter().enumerate() {
        n[(2, dof)] = sign * d[k];
    }
    n
}

fn add_bar(m: &mut ElementMatrix, dof: usize, k: [[f64; 2]; 2]) {
    let idx = [dof, NODE_DOFS + dof];
    for i in 0..2 {
        for j in 0..2 {
            m[(idx[i], idx[j])] += k[i][j];
        }
    }
}

fn add_plane(m: &mut ElementMatrix, plane: &[(usize, f64); 4], k: [[f64; 4]; 4]) {
    for i in 0..4 {
        for j in 0..4 {
            let (di, si) = plane[i];
            let (dj, sj) = plane[j];
            m[(di, dj)] += si * sj * k[i][j];
        }
    }
}

fn bending_stiffness(ei: f64, h: f64) -> [[f64; 4]; 4] {
    let c = ei / (h * h * h);
    let (h1, h2) = (h, h * h);
    [
        [12.0 * c, 6.0 * h1 * c, -12.0 * c, 6.0 * h1 * c],
        [6.0 * h1 * c, 4.0 * h2 * c, -6.0 * h1 * c, 2.0 * h2 * c],
        [-12.0 * c, -6.0 * h1 * c, 12.0 * c, -6.0 * h1 * c],
        [6.0 * h1 * c, 2.0 * h2 * c, -6.0 * h1 * c, 4.0 * h2 * c],
    ]
}

fn bending_mass(rho_a: f64, h: f64) -> [[f64; 4]; 4] {
    let c = rho_a * h / 420.0;
    let (h1, h2) = (h, h * h);
    [
        [156.0 * c, 22.0 * h1 * c, 54.0 * c, -13.0 * h1 * c],
        [22.0 * h1 * c, 4.0 * h2 * c, 13.0 * h1 * c, -3.0 * h2 * c],
        [54.0 * c, 13.0 * h1 * c, 156.0 * c, -22.0 * h1 * c],
        [-13.0 * h1 * c, -3.0 * h2 * c, -22.0 * h1 * c, 4.0 * h2 * c],
    ]
}

#[cfg(test)]
fn bending_geometric(n: f64, h: f64) -> [[f64; 4]; 4] {
    let c = n / (30.0 * h);
    let (h1, h2) = (h, h * h);
    [
        [36.0 * c, 3.0 * h1 * c, -36.0 * c, 3.0 * h1 * c],
        [3.0 * h1 * c, 4.0 * h2 * c, -3.0 * h1 * c, -h2 * c],
        [-36.0 * c, -3.0 * h1 * c, 36.0 * c, -3.0 * h1 * c],
        [3.0 * h1 * c, -h2 * c, -3.0 * h1 * c, 4.0 * h2 * c],
    ]
}

/// Element stiffness matrix for element length `h`: axial `EA`, torsion
/// `GJ`, bending `EIz` (x-y plane) and `EIy` (x-z plane).
pub fn stiffness(material: &Material, section: &Section, h: f64) -> ElementMatrix {
    let mut k = ElementMatrix::zeros();
    let ea = material.youngs_modulus * section.area / h;
    add_bar(&mut k, UX, [[ea, -ea], [-ea, ea]]);
    let gj = material.shear_modulus * section.torsion_constant / h;
    add_bar(&mut k, RX, [[gj, -gj], [-gj, gj]]);
    add_plane(
        &mut k,
        &PLANE_XY,
        bending_stiffness(material.youngs_modulus * section.iz, h),
    );
    add_plane(
        &mut k,
        &PLANE_XZ,
        bending_stiffness(material.youngs_modulus * section.iy, h),
    );
    k
}

/// Consistent element mass matrix: translational `rho A` (axial linear,
/// bending Hermite) and torsional inertia `rho Ip`; no bending rotary
/// inertia.
pub fn mass(material: &Material, section: &Section, h: f64) -> ElementMatrix {
    let mut m = ElementMatrix::zeros();
    let rho_a = material.density * section.area;
    let ca = rho_a * h / 6.0;
    add_bar(&mut m, UX, [[2.0 * ca, ca], [ca, 2.0 * ca]]);
    let ct = material.density * section.polar * h / 6.0;
    add_bar(&mut m, RX, [[2.0 * ct, ct], [ct, 2.0 * ct]]);
    add_plane(&mut m, &PLANE_XY, bending_mass(rho_a, h));
    add_plane(&mut m, &PLANE_XZ, bending_mass(rho_a, h));
    m
}

/// Consistent geometric stiffness for a constant axial force `n` (tension
/// positive), acting on the two bending planes: the reference the tests
/// hold [`geometric_stiffness_varying`] to.
#[cfg(test)]
pub fn geometric_stiffness(n: f64, h: f64) -> ElementMatrix {
    let mut k = ElementMatrix::zeros();
    add_plane(&mut k, &PLANE_XY, bending_geometric(n, h));
    add_plane(&mut k, &PLANE_XZ, bending_geometric(n, h));
    k
}

/// Geometric stiffness for an axial force varying along the element,
/// `int_0^h N(x) (H'_i H'_j) dx` per bending plane with `N` given as a
/// function of `xi = x / h`; 5-point Gauss (exact for polynomial `N` of
/// degree <= 5).
pub fn geometric_stiffness_varying(h: f64, n: impl Fn(f64) -> f64) -> ElementMatrix {
    let mut g = [[0.0; 4]; 4];
    for &(xi, w) in GAUSS5.iter() {
        let d = hermite_slope(xi, h);
        let f = w * h * n(xi);
        for i in 0..4 {
            for j in 0..4 {
                g[i][j] += f * d[i] * d[j];
            }
        }
    }
    let mut k = ElementMatrix::zeros();
    add_plane(&mut k, &PLANE_XY, g);
    add_plane(&mut k, &PLANE_XZ, g);
    k
}

/// Consistent nodal loads of a uniform force `q` per unit length (local
/// axes): `q_x h/2` per node axially, `q h [1/2, h/12, 1/2, -h/12]` per
/// bending plane in `(u, theta, u, theta)`.
pub fn uniform_load(q: [f64; 3], h: f64) -> ElementVector {
    let mut f = ElementVector::zeros();
    f[UX] = q[0] * h / 2.0;
    f[NODE_DOFS + UX] = q[0] * h / 2.0;
    let base = [h / 2.0, h * h / 12.0, h / 2.0, -h * h / 12.0];
    for (plane, qa) in [(&PLANE_XY, q[1]), (&PLANE_XZ, q[2])] {
        for k in 0..4 {
            let (dof, sign) = plane[k];
            f[dof] += sign * qa * base[k];
        }
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data() -> (Material, Section) {
        (
            Material::new(2.0e11, 0.3, 7800.0).unwrap(),
            Section::general(1e-3, 2e-7, 3e-7, 1.5e-7, 5e-7).unwrap(),
        )
    }

    /// `int_0^h f(x) dx` of a polynomial integrand of degree <= 9.
    fn integrate(h: f64, f: impl Fn(f64) -> f64) -> f64 {
        GAUSS5.iter().map(|&(xi, w)| w * h * f(xi)).sum()
    }

    #[test]
    fn gauss_rules_are_exact() {
        for p in 0..=9 {
            let exact = 1.0 / (p as f64 + 1.0);
            let g5: f64 = GAUSS5.iter().map(|&(x, w)| w * x.powi(p)).sum();
            assert!((g5 - exact).abs() < 1e-15, "5-point degree {p}");
            if p <= 7 {
                let g4: f64 = GAUSS4.iter().map(|&(x, w)| w * x.powi(p)).sum();
                assert!((g4 - exact).abs() < 1e-15, "4-point degree {p}");
            }
        }
    }

    #[test]
    fn matrices_are_symmetric() {
        let (m, s) = data();
        for a in [
            stiffness(&m, &s, 0.1),
            mass(&m, &s, 0.1),
            geometric_stiffness(3.0, 0.1),
        ] {
            assert!((a - a.transpose()).amax() < 1e-12 * a.amax());
        }
    }

    #[test]
    fn mass_and_stiffness_are_the_shape_function_integrals() {
        let (mat, sec) = data();
        let h = 0.137;
        let rho_a = mat.density * sec.area;
        let m = mass(&mat, &sec, h);
        let k = stiffness(&mat, &sec, h);
        for i in 0..ELEMENT_DOFS {
            for j in 0..ELEMENT_DOFS {
                let mij = integrate(h, |xi| {
                    let n = translation_shape(xi, h);
                    let r = rotation_shape(xi, h);
                    rho_a * (n.column(i).dot(&n.column(j)))
                        + mat.density * sec.polar * r[(0, i)] * r[(0, j)]
                });
                assert!((m[(i, j)] - mij).abs() < 1e-12 * m.amax(), "M {i} {j}");
                // Strain energy density: EA u'^2 + GJ rx'^2 + EIz v''^2 + EIy w''^2.
                let kij = integrate(h, |xi| {
                    let d = |dof: usize, xi: f64| -> [f64; 4] {
                        // Derivatives along x of (ux, rx, v', w') for unit dof.
                        let e = 1e-6;
                        let f = |x: f64| {
                            let n = translation_shape(x, h);
                            let r = rotation_shape(x, h);
                            [n[(0, dof)], r[(0, dof)], r[(2, dof)], -r[(1, dof)]]
                        };
                        let (a, b) = (f(xi + e), f(xi - e));
                        [0, 1, 2, 3].map(|q| (a[q] - b[q]) / (2.0 * e * h))
                    };
                    let (di, dj) = (d(i, xi), d(j, xi));
                    mat.youngs_modulus * sec.area * di[0] * dj[0]
                        + mat.shear_modulus * sec.torsion_constant * di[1] * dj[1]
                        + mat.youngs_modulus * sec.iz * di[2] * dj[2]
                        + mat.youngs_modulus * sec.iy * di[3] * dj[3]
                });
                assert!((k[(i, j)] - kij).abs() < 1e-6 * k.amax(), "K {i} {j}");
            }
        }
    }

    #[test]
    fn rotations_interpolate_the_nodal_dofs() {
        let h = 0.3;
        let r0 = rotation_shape(0.0, h);
        let r1 = rotation_shape(1.0, h);
        let n0 = translation_shape(0.0, h);
        let n1 = translation_shape(1.0, h);
        for a in 0..3 {
            for j in 0..ELEMENT_DOFS {
                let e0 = if j == a + 3 { 1.0 } else { 0.0 };
                let e1 = if j == NODE_DOFS + a + 3 { 1.0 } else { 0.0 };
                assert!((r0[(a, j)] - e0).abs() < 1e-14);
                assert!((r1[(a, j)] - e1).abs() < 1e-14);
                let t0 = if j == a { 1.0 } else { 0.0 };
                let t1 = if j == NODE_DOFS + a { 1.0 } else { 0.0 };
                assert!((n0[(a, j)] - t0).abs() < 1e-14);
                assert!((n1[(a, j)] - t1).abs() < 1e-14);
            }
        }
    }

    #[test]
    fn varying_geometric_stiffness_matches_the_constant_one() {
        let h = 0.05;
        let a = geometric_stiffness(-7.5, h);
        let b = geometric_stiffness_varying(h, |_| -7.5);
        assert!((a - b).amax() < 1e-12 * a.amax());
        // Linear N: the mean value for the symmetric part of the pattern.
        let c = geometric_stiffness_varying(h, |xi| 2.0 * xi);
        let d = geometric_stiffness_varying(h, |xi| 2.0 * (1.0 - xi));
        assert!(((c + d) - geometric_stiffness(2.0, h)).amax() < 1e-12);
    }

    #[test]
    fn load_vector_is_the_work_of_the_load() {
        let h = 0.2;
        let q = [1.0, -2.0, 3.0];
        let f = uniform_load(q, h);
        for j in 0..ELEMENT_DOFS {
            let w = integrate(h, |xi| {
                let n = translation_shape(xi, h);
                (0..3).map(|a| q[a] * n[(a, j)]).sum()
            });
            assert!((f[j] - w).abs() < 1e-14, "dof {j}");
        }
    }
}
