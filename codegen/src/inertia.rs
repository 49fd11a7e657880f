//! Whether a constant inertia tensor is one a body can have, for the
//! `rigid_body` component and the URDF import alike.

use nalgebra::Matrix3;

/// How far, relative to its largest entry, an inertia tensor's largest
/// principal moment may exceed the sum of the other two (moments written
/// with six digits, as URDF files often are).
pub(crate) const TRIANGLE_TOLERANCE: f64 = 1e-6;

/// Why the symmetric tensor `i` (about the centre of mass) is no body's
/// inertia, or `None`: it must be positive semi-definite, and each
/// principal moment, a sum of `m (y^2 + z^2)` over the body, at most the
/// sum of the other two (equal for a flat body), up to rounding.
pub(crate) fn inertia_problem(i: &Matrix3<f64>) -> Option<String> {
    let scale = i.abs().max();
    let moments = i.symmetric_eigenvalues();
    let smallest = moments.min();
    if smallest.is_nan() || smallest < -1e-12 * scale {
        return Some(format!(
            "the inertia tensor is not positive semi-definite (smallest principal moment \
             {smallest:e})"
        ));
    }
    let largest = moments.max();
    let others = moments.sum() - largest;
    (largest > others + TRIANGLE_TOLERANCE * scale).then(|| {
        format!(
            "the inertia tensor breaks the triangle inequality: its largest principal moment \
             {largest:e} exceeds the sum of the other two, {others:e} (no mass distribution \
             has it; tolerance {TRIANGLE_TOLERANCE:e} of the largest entry)"
        )
    })
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
            assert_eq!(inertia_problem(&ok), None);
        }
        let e = inertia_problem(&diag(1.0, 1.0, 10.0)).unwrap();
        assert!(
            e.contains("triangle inequality") && e.contains("1e1") && e.contains("2e0"),
            "{e}"
        );
        let e = inertia_problem(&diag(1.0, 1.0, -1.0)).unwrap();
        assert!(e.contains("not positive semi-definite"), "{e}");
    }
}
