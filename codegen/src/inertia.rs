//! Whether a constant inertia tensor is one a body can have, for the
//! `rigid_body` component and the URDF import alike.

use nalgebra::{Matrix3, Vector3};

/// How far, relative to the body's scale (see [`inertia_problem`]), an
/// inertia tensor's largest principal moment may exceed the sum of the
/// other two (moments written with six digits, as URDF files often are).
const TRIANGLE_TOLERANCE: f64 = 1e-6;

/// How far below zero, relative to the body's scale, a principal moment
/// may be (rounding of a tensor written as zeros and a stray `1e-35`).
const DEFINITE_TOLERANCE: f64 = 1e-12;

/// Why an inertia tensor is no body's.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum Unphysical {
    /// Not positive semi-definite: some rotation would have negative
    /// kinetic energy (the mass matrix could be indefinite).
    Indefinite { smallest: f64 },
    /// Positive semi-definite, but the largest principal moment exceeds
    /// the sum of the other two: no mass distribution has it, yet the
    /// kinetic energy stays non-negative.
    Triangle { largest: f64, others: f64 },
}

impl Unphysical {
    /// The problem in words.
    pub(crate) fn message(&self) -> String {
        match self {
            Unphysical::Indefinite { smallest } => format!(
                "the inertia tensor is not positive semi-definite (smallest principal moment \
                 {smallest:e})"
            ),
            Unphysical::Triangle { largest, others } => format!(
                "the inertia tensor breaks the triangle inequality: its largest principal moment \
                 {largest:e} exceeds the sum of the other two, {others:e} (no mass distribution \
                 has it)"
            ),
        }
    }
}

/// The moment `m |c|^2` that a body of mass `m` with its centre of mass at
/// `c` has about its frame's origin: the scale its own tensor is compared
/// with (next to that, a tensor of `1e-20` is a rounding of zero).
pub(crate) fn parallel_axis_scale(mass: f64, centre: &Vector3<f64>) -> f64 {
    (mass * centre.norm_squared()).abs()
}

/// Why the symmetric tensor `i` (about the centre of mass) is no body's
/// inertia, or `None`: it must be positive semi-definite, and each
/// principal moment, a sum of `m (y^2 + z^2)` over the body, at most the
/// sum of the other two (equal for a flat body). The tolerances are
/// relative to the larger of the tensor's largest entry and `floor`, the
/// body's moment about its frame's origin from its mass
/// ([`parallel_axis_scale`]).
pub(crate) fn inertia_problem(i: &Matrix3<f64>, floor: f64) -> Option<Unphysical> {
    let scale = i.abs().max().max(floor);
    let moments = i.symmetric_eigenvalues();
    let smallest = moments.min();
    if smallest.is_nan() || smallest < -DEFINITE_TOLERANCE * scale {
        return Some(Unphysical::Indefinite { smallest });
    }
    let largest = moments.max();
    let others = moments.sum() - largest;
    (largest > others + TRIANGLE_TOLERANCE * scale)
        .then_some(Unphysical::Triangle { largest, others })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bodies_pass_and_impossible_tensors_do_not() {
        let diag = |a: f64, b: f64, c: f64| Matrix3::from_diagonal(&[a, b, c].into());
        // A thin rod, a flat plate, a point: the limits of real bodies.
        for ok in [
            diag(1.0, 1.0, 0.0),
            diag(1.0, 2.0, 3.0),
            diag(0.0, 0.0, 0.0),
        ] {
            assert_eq!(inertia_problem(&ok, 0.0), None);
        }
        let e = inertia_problem(&diag(1.0, 1.0, 10.0), 0.0).unwrap();
        assert_eq!(
            e,
            Unphysical::Triangle {
                largest: 10.0,
                others: 2.0
            }
        );
        assert!(e.message().contains("1e1") && e.message().contains("2e0"));
        let e = inertia_problem(&diag(1.0, 1.0, -1.0), 0.0).unwrap();
        assert!(matches!(e, Unphysical::Indefinite { smallest } if smallest == -1.0));
        assert!(e.message().contains("not positive semi-definite"));
    }

    /// A tensor of rounding noise (iCub's head: only `ixz = 2.4e-35`, with
    /// 1.3 kg 0.11 m from the frame) is zero next to the body's moment
    /// about its frame, and so is a tiny triangle excess; the same tensors
    /// alone, or a real excess, are still problems.
    #[test]
    fn tolerances_follow_the_body_not_only_the_tensor() {
        let noise = Matrix3::new(0.0, 0.0, 2.4e-35, 0.0, 0.0, 0.0, 2.4e-35, 0.0, 0.0);
        let floor = parallel_axis_scale(1.33687, &Vector3::new(0.0185, -0.1108, 0.0));
        assert!((floor - 1.33687 * (0.0185f64.powi(2) + 0.1108f64.powi(2))).abs() < 1e-18);
        assert_eq!(inertia_problem(&noise, floor), None);
        assert!(matches!(
            inertia_problem(&noise, 0.0),
            Some(Unphysical::Indefinite { .. })
        ));
        let tiny = Matrix3::from_diagonal(&[1.0e-20, 1.0e-20, 5.0e-20].into());
        assert_eq!(inertia_problem(&tiny, 2.5e-4), None);
        assert!(matches!(
            inertia_problem(&tiny, 0.0),
            Some(Unphysical::Triangle { .. })
        ));
        let real = Matrix3::from_diagonal(&[1.0e-3, 1.0e-3, 6.5e-3].into());
        assert!(matches!(
            inertia_problem(&real, 5.0e-3),
            Some(Unphysical::Triangle { .. })
        ));
        let indefinite = Matrix3::from_diagonal(&[1.0e-3, 1.0e-3, -1.0e-9].into());
        assert!(matches!(
            inertia_problem(&indefinite, 5.0e-3),
            Some(Unphysical::Indefinite { .. })
        ));
    }
}
