//! A system driven only by a rheonomic constraint (no actuators):
//! scenes/driven_cart_pendulum.toml, a cart whose position is prescribed by
//! `x - a sin(w t) = 0`, carrying a free pendulum. The integrated motion
//! keeps the constraint, the pendulum follows its own base-excited equation
//! `phi'' = -(x''(t) cos(phi) + g sin(phi)) / l` (integrated here
//! independently), and the constraint force (the force that moves the cart)
//! equals its closed form `lambda = (mc + m) x'' + m l (phi'' cos(phi) -
//! phi'^2 sin(phi))`.

use flexdyn::runtime::{accelerations, DynamicsConfig, GaussLegendre4, IntegratorOf, Model, State};
use flexdyn::scenes::driven_cart_pendulum::DrivenCartPendulum;
use nalgebra::SVector;

// Parameters exactly as written in scenes/driven_cart_pendulum.toml.
const MC: f64 = 2.0;
const M: f64 = 0.5;
const L: f64 = 0.4;
const A: f64 = 0.1;
const W: f64 = 4.0;
const G: f64 = 9.81;

fn drive_acceleration(t: f64) -> f64 {
    -A * W * W * (W * t).sin()
}

/// The pendulum's reduced equation under the prescribed cart motion.
fn phi_dd(t: f64, phi: f64) -> f64 {
    -(drive_acceleration(t) * phi.cos() + G * phi.sin()) / L
}

/// Classical RK4 on the reduced equation `(phi, phi')`, independent of the
/// generated model and of the runtime.
fn reduced_step(t: f64, y: [f64; 2], h: f64) -> [f64; 2] {
    let f = |t: f64, y: [f64; 2]| [y[1], phi_dd(t, y[0])];
    let add = |y: [f64; 2], k: [f64; 2], c: f64| [y[0] + c * k[0], y[1] + c * k[1]];
    let k1 = f(t, y);
    let k2 = f(t + h / 2.0, add(y, k1, h / 2.0));
    let k3 = f(t + h / 2.0, add(y, k2, h / 2.0));
    let k4 = f(t + h, add(y, k3, h));
    [
        y[0] + h / 6.0 * (k1[0] + 2.0 * k2[0] + 2.0 * k3[0] + k4[0]),
        y[1] + h / 6.0 * (k1[1] + 2.0 * k2[1] + 2.0 * k3[1] + k4[1]),
    ]
}

#[test]
fn a_prescribed_cart_motion_drives_the_pendulum_with_the_closed_form_force() {
    let model = DrivenCartPendulum;
    assert_eq!(<DrivenCartPendulum as Model<2, 1, 0>>::ACTUATORS.len(), 0);
    let none = SVector::<f64, 0>::zeros();
    // Consistent start: x(0) = 0, x'(0) = a w; the pendulum at 0.3 rad, at rest.
    let mut s = State::new(SVector::from([0.0, 0.3]), SVector::from([A * W, 0.0]), 0.0);
    let mut reduced = [0.3, 0.0];
    let mut gl = GaussLegendre4::default();
    let h = 1e-3;
    let (mut max_drive, mut max_phi, mut max_force) = (0.0f64, 0.0f64, 0.0f64);
    for _ in 0..3000 {
        // Constraint force at this state against the closed form.
        let acc = accelerations(&model, &DynamicsConfig::default(), &s.q, &s.qd, s.t, &none)
            .expect("forward dynamics");
        let (t, phi, phid) = (s.t, s.q[1], s.qd[1]);
        let xdd = drive_acceleration(t);
        let pdd = -(xdd * phi.cos() + G * phi.sin()) / L;
        let lambda = (MC + M) * xdd + M * L * (pdd * phi.cos() - phid * phid * phi.sin());
        max_force = max_force.max((acc.lambda[0] - lambda).abs());
        gl.step(&model, &mut s, &none, h).expect("step");
        reduced = reduced_step(t, reduced, h);
        max_drive = max_drive.max((s.q[0] - A * (W * s.t).sin()).abs());
        max_phi = max_phi.max((s.q[1] - reduced[0]).abs());
    }
    eprintln!(
        "driven cart-pendulum, 3 s at 1 ms: max |x - a sin(w t)| {max_drive:.2e} m, \
         max |phi - phi_reduced| {max_phi:.2e} rad, max |lambda - closed form| {max_force:.2e} N"
    );
    // The cart force swings by about (mc + m) a w^2 = 4 N.
    assert!(max_force < 1e-9, "constraint force off by {max_force:e} N");
    assert!(max_drive < 1e-9, "drive constraint off by {max_drive:e} m");
    assert!(
        max_phi < 1e-8,
        "pendulum off its reduced equation by {max_phi:e} rad"
    );
}
