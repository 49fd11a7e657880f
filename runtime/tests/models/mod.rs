//! Hand-written test models with closed-form equations of motion, and generic
//! helpers. Each model's `mass_matrix`, `bias`, constraint functions are
//! checked against its energy functions and constraint residuals by finite
//! differences in `model_consistency.rs`, so the solver tests rest on
//! independently verified equations.
#![allow(dead_code)]

use flexdyn_runtime::control::Target;
use flexdyn_runtime::nalgebra::{SMatrix, SVector};
use flexdyn_runtime::{Model, State};

pub type V<const N: usize> = SVector<f64, N>;
pub type Mat<const R: usize, const C: usize> = SMatrix<f64, R, C>;

/// The four constraint functions of a model without constraints (`NC = 0`).
macro_rules! unconstrained {
    ($nq:tt) => {
        fn constraints(&self, _q: &V<$nq>, _t: f64, _phi: &mut V<0>) {}
        fn constraint_jacobian(&self, _q: &V<$nq>, _t: f64, _j: &mut Mat<0, $nq>) {}
        fn constraint_time_derivative(&self, _q: &V<$nq>, _t: f64, _p: &mut V<0>) {}
        fn constraint_rhs(&self, _q: &V<$nq>, _qd: &V<$nq>, _t: f64, _g: &mut V<0>) {}
    };
}

// ---------------------------------------------------------------------------
// Simple pendulum: point mass m on a massless rod of length l, angle from the
// downward vertical, viscous joint damping c, joint torque.
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct Pendulum {
    pub m: f64,
    pub l: f64,
    pub g: f64,
    pub c: f64,
}

impl Default for Pendulum {
    fn default() -> Self {
        Pendulum {
            m: 1.0,
            l: 1.0,
            g: 9.81,
            c: 0.0,
        }
    }
}

impl Model<1, 0, 1> for Pendulum {
    const NAME: &'static str = "pendulum";
    const COORDINATES: [&'static str; 1] = ["theta"];
    const ACTUATORS: [&'static str; 1] = ["torque"];
    fn mass_matrix(&self, _q: &V<1>, _t: f64, m: &mut Mat<1, 1>) {
        m[(0, 0)] = self.m * self.l * self.l;
    }
    fn bias(&self, q: &V<1>, qd: &V<1>, _t: f64, h: &mut V<1>) {
        h[0] = self.m * self.g * self.l * q[0].sin() + self.c * qd[0];
    }
    unconstrained!(1);
    fn actuator_map(&self, b: &mut Mat<1, 1>) {
        b[(0, 0)] = 1.0;
    }
    fn kinetic_energy(&self, _q: &V<1>, qd: &V<1>, _t: f64) -> f64 {
        0.5 * self.m * self.l * self.l * qd[0] * qd[0]
    }
    fn potential_energy(&self, q: &V<1>, _t: f64) -> f64 {
        -self.m * self.g * self.l * q[0].cos()
    }
}

// ---------------------------------------------------------------------------
// Double pendulum, point masses, absolute angles from the downward vertical.
// Joint torques: tau1 at the base, tau2 at the elbow (acts on theta2 - theta1),
// so B = [[1, -1], [0, 1]].
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct DoublePendulum {
    pub m1: f64,
    pub m2: f64,
    pub l1: f64,
    pub l2: f64,
    pub g: f64,
}

impl Default for DoublePendulum {
    fn default() -> Self {
        DoublePendulum {
            m1: 1.0,
            m2: 0.7,
            l1: 1.0,
            l2: 0.8,
            g: 9.81,
        }
    }
}

impl Model<2, 0, 2> for DoublePendulum {
    const NAME: &'static str = "double_pendulum";
    const COORDINATES: [&'static str; 2] = ["theta1", "theta2"];
    const ACTUATORS: [&'static str; 2] = ["shoulder", "elbow"];
    fn mass_matrix(&self, q: &V<2>, _t: f64, m: &mut Mat<2, 2>) {
        let c = (q[0] - q[1]).cos();
        m[(0, 0)] = (self.m1 + self.m2) * self.l1 * self.l1;
        m[(0, 1)] = self.m2 * self.l1 * self.l2 * c;
        m[(1, 0)] = m[(0, 1)];
        m[(1, 1)] = self.m2 * self.l2 * self.l2;
    }
    fn bias(&self, q: &V<2>, qd: &V<2>, _t: f64, h: &mut V<2>) {
        let s = (q[0] - q[1]).sin();
        let k = self.m2 * self.l1 * self.l2;
        h[0] = k * s * qd[1] * qd[1] + (self.m1 + self.m2) * self.g * self.l1 * q[0].sin();
        h[1] = -k * s * qd[0] * qd[0] + self.m2 * self.g * self.l2 * q[1].sin();
    }
    unconstrained!(2);
    fn actuator_map(&self, b: &mut Mat<2, 2>) {
        *b = Mat::<2, 2>::new(1.0, -1.0, 0.0, 1.0);
    }
    fn kinetic_energy(&self, q: &V<2>, qd: &V<2>, _t: f64) -> f64 {
        0.5 * (self.m1 + self.m2) * self.l1 * self.l1 * qd[0] * qd[0]
            + 0.5 * self.m2 * self.l2 * self.l2 * qd[1] * qd[1]
            + self.m2 * self.l1 * self.l2 * qd[0] * qd[1] * (q[0] - q[1]).cos()
    }
    fn potential_energy(&self, q: &V<2>, _t: f64) -> f64 {
        -(self.m1 + self.m2) * self.g * self.l1 * q[0].cos()
            - self.m2 * self.g * self.l2 * q[1].cos()
    }
}

// ---------------------------------------------------------------------------
// Slider-crank in redundant coordinates q = (theta, phi, x): crank angle,
// connecting-rod angle (rod points from the crank pin to the slider, at angle
// -phi), slider position on the x axis. Two closure constraints. Uniform
// crank (m1, r) and rod (m2, l), slider mass m3, gravity along -y, optional
// viscous slider damping. Actuator: crank torque.
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct SliderCrank {
    pub r: f64,
    pub l: f64,
    pub m1: f64,
    pub m2: f64,
    pub m3: f64,
    pub g: f64,
    pub slider_damping: f64,
}

impl Default for SliderCrank {
    fn default() -> Self {
        SliderCrank {
            r: 0.1,
            l: 0.3,
            m1: 1.0,
            m2: 0.5,
            m3: 0.8,
            g: 9.81,
            slider_damping: 0.0,
        }
    }
}

impl SliderCrank {
    /// Assembled state for a crank angle and crank rate.
    pub fn consistent_state(&self, theta: f64, theta_dot: f64) -> State<3> {
        let phi = (self.r * theta.sin() / self.l).asin();
        let x = self.r * theta.cos() + self.l * phi.cos();
        // r cos(th) thd - l cos(phi) phid = 0 ; xd = -r sin th thd - l sin phi phid
        let phid = self.r * theta.cos() * theta_dot / (self.l * phi.cos());
        let xd = -self.r * theta.sin() * theta_dot - self.l * phi.sin() * phid;
        State::new(
            V::<3>::new(theta, phi, x),
            V::<3>::new(theta_dot, phid, xd),
            0.0,
        )
    }
}

impl Model<3, 2, 1> for SliderCrank {
    const NAME: &'static str = "slider_crank";
    const COORDINATES: [&'static str; 3] = ["theta", "phi", "x"];
    const ACTUATORS: [&'static str; 1] = ["crank_torque"];
    fn mass_matrix(&self, q: &V<3>, _t: f64, m: &mut Mat<3, 3>) {
        let c = 0.5 * self.m2 * self.r * self.l;
        m.fill(0.0);
        m[(0, 0)] = self.m1 * self.r * self.r / 3.0 + self.m2 * self.r * self.r;
        m[(0, 1)] = -c * (q[0] + q[1]).cos();
        m[(1, 0)] = m[(0, 1)];
        m[(1, 1)] = self.m2 * self.l * self.l / 3.0;
        m[(2, 2)] = self.m3;
    }
    fn bias(&self, q: &V<3>, qd: &V<3>, _t: f64, h: &mut V<3>) {
        let sp = 0.5 * self.m2 * self.r * self.l * (q[0] + q[1]).sin();
        h[0] = sp * qd[1] * qd[1] + (0.5 * self.m1 + self.m2) * self.g * self.r * q[0].cos();
        h[1] = sp * qd[0] * qd[0] - 0.5 * self.m2 * self.g * self.l * q[1].cos();
        h[2] = self.slider_damping * qd[2];
    }
    fn constraints(&self, q: &V<3>, _t: f64, phi: &mut V<2>) {
        phi[0] = self.r * q[0].cos() + self.l * q[1].cos() - q[2];
        phi[1] = self.r * q[0].sin() - self.l * q[1].sin();
    }
    fn constraint_jacobian(&self, q: &V<3>, _t: f64, j: &mut Mat<2, 3>) {
        *j = Mat::<2, 3>::new(
            -self.r * q[0].sin(),
            -self.l * q[1].sin(),
            -1.0,
            self.r * q[0].cos(),
            -self.l * q[1].cos(),
            0.0,
        );
    }
    fn constraint_time_derivative(&self, _q: &V<3>, _t: f64, p: &mut V<2>) {
        p.fill(0.0);
    }
    fn constraint_rhs(&self, q: &V<3>, qd: &V<3>, _t: f64, g: &mut V<2>) {
        let (a, b) = (qd[0] * qd[0], qd[1] * qd[1]);
        g[0] = self.r * q[0].cos() * a + self.l * q[1].cos() * b;
        g[1] = self.r * q[0].sin() * a - self.l * q[1].sin() * b;
    }
    fn actuator_map(&self, b: &mut Mat<3, 1>) {
        *b = Mat::<3, 1>::new(1.0, 0.0, 0.0);
    }
    fn kinetic_energy(&self, q: &V<3>, qd: &V<3>, _t: f64) -> f64 {
        let ic = self.m1 * self.r * self.r / 3.0;
        // Rod centre velocity from the kinematics.
        let vx = -self.r * q[0].sin() * qd[0] - 0.5 * self.l * q[1].sin() * qd[1];
        let vy = self.r * q[0].cos() * qd[0] - 0.5 * self.l * q[1].cos() * qd[1];
        0.5 * ic * qd[0] * qd[0]
            + 0.5 * self.m2 * (vx * vx + vy * vy)
            + 0.5 * self.m2 * self.l * self.l / 12.0 * qd[1] * qd[1]
            + 0.5 * self.m3 * qd[2] * qd[2]
    }
    fn potential_energy(&self, q: &V<3>, _t: f64) -> f64 {
        let yc1 = 0.5 * self.r * q[0].sin();
        let yc2 = self.r * q[0].sin() - 0.5 * self.l * q[1].sin();
        self.g * (self.m1 * yc1 + self.m2 * yc2)
    }
}

// ---------------------------------------------------------------------------
// Slider-crank carrying an absorber: a mass m4 at position z on the slider's
// axis, tied to the slider by a spring (stiffness k, rest offset d0) and a
// dashpot c. q = (theta, phi, x, z); the closure constraints and the crank
// torque are the slider-crank's; z is unconstrained and unactuated.
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct AbsorberCrank {
    pub crank: SliderCrank,
    pub m4: f64,
    pub k: f64,
    pub d0: f64,
    pub c: f64,
}

impl Default for AbsorberCrank {
    fn default() -> Self {
        AbsorberCrank {
            crank: SliderCrank::default(),
            m4: 0.3,
            k: 270.0,
            d0: 0.1,
            c: 0.0,
        }
    }
}

impl AbsorberCrank {
    fn sub(q: &V<4>) -> V<3> {
        V::<3>::new(q[0], q[1], q[2])
    }
    /// Spring stretch and its rate.
    fn stretch(&self, q: &V<4>, qd: &V<4>) -> (f64, f64) {
        (q[3] - q[2] - self.d0, qd[3] - qd[2])
    }
}

impl Model<4, 2, 1> for AbsorberCrank {
    const NAME: &'static str = "absorber_crank";
    const COORDINATES: [&'static str; 4] = ["theta", "phi", "x", "z"];
    const ACTUATORS: [&'static str; 1] = ["crank_torque"];
    fn mass_matrix(&self, q: &V<4>, t: f64, m: &mut Mat<4, 4>) {
        let mut m3 = Mat::<3, 3>::zeros();
        self.crank.mass_matrix(&Self::sub(q), t, &mut m3);
        m.fill(0.0);
        m.fixed_view_mut::<3, 3>(0, 0).copy_from(&m3);
        m[(3, 3)] = self.m4;
    }
    fn bias(&self, q: &V<4>, qd: &V<4>, t: f64, h: &mut V<4>) {
        let mut h3 = V::<3>::zeros();
        self.crank.bias(&Self::sub(q), &Self::sub(qd), t, &mut h3);
        let (e, ed) = self.stretch(q, qd);
        let f = self.k * e + self.c * ed;
        *h = V::<4>::new(h3[0], h3[1], h3[2] - f, f);
    }
    fn constraints(&self, q: &V<4>, t: f64, phi: &mut V<2>) {
        self.crank.constraints(&Self::sub(q), t, phi);
    }
    fn constraint_jacobian(&self, q: &V<4>, t: f64, j: &mut Mat<2, 4>) {
        let mut j3 = Mat::<2, 3>::zeros();
        self.crank.constraint_jacobian(&Self::sub(q), t, &mut j3);
        j.fill(0.0);
        j.fixed_view_mut::<2, 3>(0, 0).copy_from(&j3);
    }
    fn constraint_time_derivative(&self, _q: &V<4>, _t: f64, p: &mut V<2>) {
        p.fill(0.0);
    }
    fn constraint_rhs(&self, q: &V<4>, qd: &V<4>, t: f64, g: &mut V<2>) {
        self.crank
            .constraint_rhs(&Self::sub(q), &Self::sub(qd), t, g);
    }
    fn actuator_map(&self, b: &mut Mat<4, 1>) {
        *b = Mat::<4, 1>::new(1.0, 0.0, 0.0, 0.0);
    }
    fn kinetic_energy(&self, q: &V<4>, qd: &V<4>, t: f64) -> f64 {
        self.crank.kinetic_energy(&Self::sub(q), &Self::sub(qd), t) + 0.5 * self.m4 * qd[3] * qd[3]
    }
    fn potential_energy(&self, q: &V<4>, t: f64) -> f64 {
        let (e, _) = self.stretch(q, &V::<4>::zeros());
        self.crank.potential_energy(&Self::sub(q), t) + 0.5 * self.k * e * e
    }
}

// ---------------------------------------------------------------------------
// Five-bar planar parallel robot in redundant coordinates
// q = (theta1, phi1, theta2, phi2, x, y): absolute angles of the proximal and
// distal links of both legs and the platform point. Bases at (-d/2, 0) and
// (d/2, 0); uniform links; point-mass platform; gravity along -y.
// Four closure constraints (each leg's tip = platform). Actuators: base
// torques on theta1, theta2; with NU = 3 also an elbow torque in leg 1
// (redundant actuation).
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct FiveBar<const NU: usize> {
    pub d: f64,
    pub l1: f64,
    pub l2: f64,
    pub m1: f64,
    pub m2: f64,
    pub mp: f64,
    pub g: f64,
}

impl<const NU: usize> Default for FiveBar<NU> {
    fn default() -> Self {
        FiveBar {
            d: 0.2,
            l1: 0.25,
            l2: 0.3,
            m1: 0.4,
            m2: 0.3,
            mp: 0.5,
            g: 9.81,
        }
    }
}

impl<const NU: usize> FiveBar<NU> {
    pub fn base(&self, leg: usize) -> (f64, f64) {
        if leg == 0 {
            (-0.5 * self.d, 0.0)
        } else {
            (0.5 * self.d, 0.0)
        }
    }

    /// Closed-form inverse kinematics, elbows outward.
    pub fn assemble(&self, x: f64, y: f64) -> V<6> {
        let mut q = V::<6>::zeros();
        for leg in 0..2 {
            let (ax, ay) = self.base(leg);
            let (dx, dy) = (x - ax, y - ay);
            let dist = (dx * dx + dy * dy).sqrt();
            let psi = dy.atan2(dx);
            let ca = (self.l1 * self.l1 + dist * dist - self.l2 * self.l2) / (2.0 * self.l1 * dist);
            let alpha = ca.clamp(-1.0, 1.0).acos();
            let theta = if leg == 0 { psi + alpha } else { psi - alpha };
            let (ex, ey) = (ax + self.l1 * theta.cos(), ay + self.l1 * theta.sin());
            q[2 * leg] = theta;
            q[2 * leg + 1] = (y - ey).atan2(x - ex);
        }
        q[4] = x;
        q[5] = y;
        q
    }
}

/// The five-bar's platform on a circle of radius 0.04 about (0, 0.32), once
/// in two seconds.
pub fn platform_circle(t: f64) -> Target<2> {
    let w = core::f64::consts::PI;
    let (s, c) = (w * t).sin_cos();
    Target {
        position: V::<2>::new(0.04 * c, 0.32 + 0.04 * s),
        velocity: V::<2>::new(-0.04 * w * s, 0.04 * w * c),
        acceleration: V::<2>::new(-0.04 * w * w * c, -0.04 * w * w * s),
    }
}

impl<const NU: usize> Model<6, 4, NU> for FiveBar<NU> {
    const NAME: &'static str = "five_bar";
    const COORDINATES: [&'static str; 6] = ["theta1", "phi1", "theta2", "phi2", "x", "y"];
    const ACTUATORS: [&'static str; NU] = ["actuator"; NU];
    fn mass_matrix(&self, q: &V<6>, _t: f64, m: &mut Mat<6, 6>) {
        m.fill(0.0);
        for leg in 0..2 {
            let (i, j) = (2 * leg, 2 * leg + 1);
            m[(i, i)] = self.m1 * self.l1 * self.l1 / 3.0 + self.m2 * self.l1 * self.l1;
            m[(i, j)] = 0.5 * self.m2 * self.l1 * self.l2 * (q[i] - q[j]).cos();
            m[(j, i)] = m[(i, j)];
            m[(j, j)] = self.m2 * self.l2 * self.l2 / 3.0;
        }
        m[(4, 4)] = self.mp;
        m[(5, 5)] = self.mp;
    }
    fn bias(&self, q: &V<6>, qd: &V<6>, _t: f64, h: &mut V<6>) {
        for leg in 0..2 {
            let (i, j) = (2 * leg, 2 * leg + 1);
            let cs = 0.5 * self.m2 * self.l1 * self.l2 * (q[i] - q[j]).sin();
            h[i] = cs * qd[j] * qd[j] + (0.5 * self.m1 + self.m2) * self.g * self.l1 * q[i].cos();
            h[j] = -cs * qd[i] * qd[i] + 0.5 * self.m2 * self.g * self.l2 * q[j].cos();
        }
        h[4] = 0.0;
        h[5] = self.mp * self.g;
    }
    fn constraints(&self, q: &V<6>, _t: f64, phi: &mut V<4>) {
        for leg in 0..2 {
            let (ax, ay) = self.base(leg);
            let (th, ph) = (q[2 * leg], q[2 * leg + 1]);
            phi[2 * leg] = ax + self.l1 * th.cos() + self.l2 * ph.cos() - q[4];
            phi[2 * leg + 1] = ay + self.l1 * th.sin() + self.l2 * ph.sin() - q[5];
        }
    }
    fn constraint_jacobian(&self, q: &V<6>, _t: f64, jac: &mut Mat<4, 6>) {
        jac.fill(0.0);
        for leg in 0..2 {
            let (i, j) = (2 * leg, 2 * leg + 1);
            let (th, ph) = (q[i], q[j]);
            jac[(2 * leg, i)] = -self.l1 * th.sin();
            jac[(2 * leg, j)] = -self.l2 * ph.sin();
            jac[(2 * leg, 4)] = -1.0;
            jac[(2 * leg + 1, i)] = self.l1 * th.cos();
            jac[(2 * leg + 1, j)] = self.l2 * ph.cos();
            jac[(2 * leg + 1, 5)] = -1.0;
        }
    }
    fn constraint_time_derivative(&self, _q: &V<6>, _t: f64, p: &mut V<4>) {
        p.fill(0.0);
    }
    fn constraint_rhs(&self, q: &V<6>, qd: &V<6>, _t: f64, g: &mut V<4>) {
        for leg in 0..2 {
            let (i, j) = (2 * leg, 2 * leg + 1);
            let (a, b) = (qd[i] * qd[i], qd[j] * qd[j]);
            g[2 * leg] = self.l1 * q[i].cos() * a + self.l2 * q[j].cos() * b;
            g[2 * leg + 1] = self.l1 * q[i].sin() * a + self.l2 * q[j].sin() * b;
        }
    }
    fn actuator_map(&self, b: &mut Mat<6, NU>) {
        b.fill(0.0);
        if NU > 0 {
            b[(0, 0)] = 1.0;
        }
        if NU > 1 {
            b[(2, 1)] = 1.0;
        }
        if NU > 2 {
            b[(0, 2)] = -1.0;
            b[(1, 2)] = 1.0;
        }
    }
    fn kinetic_energy(&self, q: &V<6>, qd: &V<6>, _t: f64) -> f64 {
        let mut t = 0.5 * self.mp * (qd[4] * qd[4] + qd[5] * qd[5]);
        for leg in 0..2 {
            let (th, ph, thd, phd) = (q[2 * leg], q[2 * leg + 1], qd[2 * leg], qd[2 * leg + 1]);
            t += 0.5 * (self.m1 * self.l1 * self.l1 / 3.0) * thd * thd;
            let vx = -self.l1 * th.sin() * thd - 0.5 * self.l2 * ph.sin() * phd;
            let vy = self.l1 * th.cos() * thd + 0.5 * self.l2 * ph.cos() * phd;
            t += 0.5 * self.m2 * (vx * vx + vy * vy)
                + 0.5 * (self.m2 * self.l2 * self.l2 / 12.0) * phd * phd;
        }
        t
    }
    fn potential_energy(&self, q: &V<6>, _t: f64) -> f64 {
        let mut v = self.mp * self.g * q[5];
        for leg in 0..2 {
            let (th, ph) = (q[2 * leg], q[2 * leg + 1]);
            v += self.m1 * self.g * 0.5 * self.l1 * th.sin();
            v += self.m2 * self.g * (self.l1 * th.sin() + 0.5 * self.l2 * ph.sin());
        }
        v
    }
}

// ---------------------------------------------------------------------------
// Spring-mass chain: wall -k[0]- m[0] -k[1]- m[1] - ... ; optional dashpots
// in parallel with the springs; force input on mass 0. Provides analytic bias
// Jacobians when `analytic` is set.
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct SpringChain<const N: usize> {
    pub m: [f64; N],
    pub k: [f64; N],
    pub c: [f64; N],
    pub analytic: bool,
}

impl<const N: usize> SpringChain<N> {
    pub fn stiffness(&self) -> Mat<N, N> {
        let mut k = Mat::<N, N>::zeros();
        for i in 0..N {
            k[(i, i)] += self.k[i];
            if i > 0 {
                k[(i - 1, i - 1)] += self.k[i];
                k[(i - 1, i)] -= self.k[i];
                k[(i, i - 1)] -= self.k[i];
            }
        }
        k
    }
    pub fn damping(&self) -> Mat<N, N> {
        let mut c = Mat::<N, N>::zeros();
        for i in 0..N {
            c[(i, i)] += self.c[i];
            if i > 0 {
                c[(i - 1, i - 1)] += self.c[i];
                c[(i - 1, i)] -= self.c[i];
                c[(i, i - 1)] -= self.c[i];
            }
        }
        c
    }
    pub fn mass(&self) -> Mat<N, N> {
        Mat::<N, N>::from_diagonal(&V::<N>::from_row_slice(&self.m))
    }
}

impl SpringChain<4> {
    /// One heavy mass on a soft spring (about 1 Hz) carrying three light
    /// masses on stiff springs: highest mode about 3 kHz.
    pub fn stiff() -> Self {
        SpringChain {
            m: [1.0, 0.01, 0.01, 0.01],
            k: [40.0, 1e6, 1e6, 1e6],
            c: [0.0; 4],
            analytic: false,
        }
    }
}

impl<const N: usize> Model<N, 0, 1> for SpringChain<N> {
    const NAME: &'static str = "spring_chain";
    const COORDINATES: [&'static str; N] = ["x"; N];
    const ACTUATORS: [&'static str; 1] = ["force"];
    fn mass_matrix(&self, _q: &V<N>, _t: f64, m: &mut Mat<N, N>) {
        *m = self.mass();
    }
    fn bias(&self, q: &V<N>, qd: &V<N>, _t: f64, h: &mut V<N>) {
        *h = self.stiffness() * q + self.damping() * qd;
    }
    unconstrained!(N);
    fn actuator_map(&self, b: &mut Mat<N, 1>) {
        b.fill(0.0);
        if N > 0 {
            b[(0, 0)] = 1.0;
        }
    }
    fn kinetic_energy(&self, _q: &V<N>, qd: &V<N>, _t: f64) -> f64 {
        (0..N).map(|i| 0.5 * self.m[i] * qd[i] * qd[i]).sum()
    }
    fn potential_energy(&self, q: &V<N>, _t: f64) -> f64 {
        (0..N)
            .map(|i| {
                let e = if i == 0 { q[0] } else { q[i] - q[i - 1] };
                0.5 * self.k[i] * e * e
            })
            .sum()
    }
    fn bias_jacobians(
        &self,
        _q: &V<N>,
        _qd: &V<N>,
        _t: f64,
        h_q: &mut Mat<N, N>,
        h_qd: &mut Mat<N, N>,
    ) -> bool {
        if self.analytic {
            *h_q = self.stiffness();
            *h_qd = self.damping();
        }
        self.analytic
    }
}

// ---------------------------------------------------------------------------
// Elastic pendulum: point mass on a stiff spring, q = (r, theta). The axial
// mode is at sqrt(k/m) (kHz); the swing mode at about 0.5 Hz.
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct ElasticPendulum {
    pub m: f64,
    pub k: f64,
    pub l0: f64,
    pub g: f64,
}

impl Default for ElasticPendulum {
    fn default() -> Self {
        let f = 2000.0; // Hz
        let w = 2.0 * core::f64::consts::PI * f;
        ElasticPendulum {
            m: 1.0,
            k: w * w,
            l0: 1.0,
            g: 9.81,
        }
    }
}

impl Model<2, 0, 1> for ElasticPendulum {
    const NAME: &'static str = "elastic_pendulum";
    const COORDINATES: [&'static str; 2] = ["r", "theta"];
    const ACTUATORS: [&'static str; 1] = ["torque"];
    fn mass_matrix(&self, q: &V<2>, _t: f64, m: &mut Mat<2, 2>) {
        *m = Mat::<2, 2>::new(self.m, 0.0, 0.0, self.m * q[0] * q[0]);
    }
    fn bias(&self, q: &V<2>, qd: &V<2>, _t: f64, h: &mut V<2>) {
        let (r, th) = (q[0], q[1]);
        h[0] = -self.m * r * qd[1] * qd[1] + self.k * (r - self.l0) - self.m * self.g * th.cos();
        h[1] = 2.0 * self.m * r * qd[0] * qd[1] + self.m * self.g * r * th.sin();
    }
    unconstrained!(2);
    fn actuator_map(&self, b: &mut Mat<2, 1>) {
        *b = Mat::<2, 1>::new(0.0, 1.0);
    }
    fn kinetic_energy(&self, q: &V<2>, qd: &V<2>, _t: f64) -> f64 {
        0.5 * self.m * (qd[0] * qd[0] + q[0] * q[0] * qd[1] * qd[1])
    }
    fn potential_energy(&self, q: &V<2>, _t: f64) -> f64 {
        0.5 * self.k * (q[0] - self.l0) * (q[0] - self.l0) - self.m * self.g * q[0] * q[1].cos()
    }
}

// ---------------------------------------------------------------------------
// Rotating arm in a horizontal plane: hub inertia j, angle theta (torque
// input), carrying a slider of mass m on a radial spring (stiffness k, rest
// radius r0, viscous damping c along the arm) at radius r. q = (theta, r).
// The slider is the "elastic" coordinate of a servo test: with theta(t)
// prescribed it obeys m r'' + c r' + k (r - r0) = m r theta'^2.
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct RotatingArm {
    pub j: f64,
    pub m: f64,
    pub k: f64,
    pub r0: f64,
    pub c: f64,
}

impl Default for RotatingArm {
    fn default() -> Self {
        RotatingArm {
            j: 0.5,
            m: 1.0,
            k: 400.0,
            r0: 0.5,
            c: 0.0,
        }
    }
}

impl Model<2, 0, 1> for RotatingArm {
    const NAME: &'static str = "rotating_arm";
    const COORDINATES: [&'static str; 2] = ["theta", "r"];
    const ACTUATORS: [&'static str; 1] = ["hub_torque"];
    fn mass_matrix(&self, q: &V<2>, _t: f64, m: &mut Mat<2, 2>) {
        *m = Mat::<2, 2>::new(self.j + self.m * q[1] * q[1], 0.0, 0.0, self.m);
    }
    fn bias(&self, q: &V<2>, qd: &V<2>, _t: f64, h: &mut V<2>) {
        let r = q[1];
        h[0] = 2.0 * self.m * r * qd[1] * qd[0];
        h[1] = -self.m * r * qd[0] * qd[0] + self.k * (r - self.r0) + self.c * qd[1];
    }
    unconstrained!(2);
    fn actuator_map(&self, b: &mut Mat<2, 1>) {
        *b = Mat::<2, 1>::new(1.0, 0.0);
    }
    fn kinetic_energy(&self, q: &V<2>, qd: &V<2>, _t: f64) -> f64 {
        0.5 * (self.j + self.m * q[1] * q[1]) * qd[0] * qd[0] + 0.5 * self.m * qd[1] * qd[1]
    }
    fn potential_energy(&self, q: &V<2>, _t: f64) -> f64 {
        0.5 * self.k * (q[1] - self.r0) * (q[1] - self.r0)
    }
}

// ---------------------------------------------------------------------------
// Two free carts of masses m0, m1 on a line, with crossed actuators:
// actuator 0 pushes cart 1, actuator 1 pushes cart 0 (B = [[0, 1], [1, 0]]).
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct CrossedCarts {
    pub m0: f64,
    pub m1: f64,
}

impl Default for CrossedCarts {
    fn default() -> Self {
        CrossedCarts { m0: 2.0, m1: 0.5 }
    }
}

impl Model<2, 0, 2> for CrossedCarts {
    const NAME: &'static str = "crossed_carts";
    const COORDINATES: [&'static str; 2] = ["x0", "x1"];
    const ACTUATORS: [&'static str; 2] = ["push_1", "push_0"];
    fn mass_matrix(&self, _q: &V<2>, _t: f64, m: &mut Mat<2, 2>) {
        *m = Mat::<2, 2>::new(self.m0, 0.0, 0.0, self.m1);
    }
    fn bias(&self, _q: &V<2>, _qd: &V<2>, _t: f64, h: &mut V<2>) {
        h.fill(0.0);
    }
    unconstrained!(2);
    fn actuator_map(&self, b: &mut Mat<2, 2>) {
        *b = Mat::<2, 2>::new(0.0, 1.0, 1.0, 0.0);
    }
    fn kinetic_energy(&self, _q: &V<2>, qd: &V<2>, _t: f64) -> f64 {
        0.5 * (self.m0 * qd[0] * qd[0] + self.m1 * qd[1] * qd[1])
    }
    fn potential_energy(&self, _q: &V<2>, _t: f64) -> f64 {
        0.0
    }
}

// ---------------------------------------------------------------------------
// Pendulum in Cartesian coordinates (x, y) with the constraint
// x^2 + y^2 - L^2 = 0; its Jacobian vanishes at the origin. Force input on x.
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct CartesianPendulum {
    pub m: f64,
    pub l: f64,
    pub g: f64,
}

impl Default for CartesianPendulum {
    fn default() -> Self {
        CartesianPendulum {
            m: 1.0,
            l: 1.0,
            g: 9.81,
        }
    }
}

impl Model<2, 1, 1> for CartesianPendulum {
    const NAME: &'static str = "cartesian_pendulum";
    const COORDINATES: [&'static str; 2] = ["x", "y"];
    const ACTUATORS: [&'static str; 1] = ["fx"];
    fn mass_matrix(&self, _q: &V<2>, _t: f64, m: &mut Mat<2, 2>) {
        *m = Mat::<2, 2>::identity() * self.m;
    }
    fn bias(&self, _q: &V<2>, _qd: &V<2>, _t: f64, h: &mut V<2>) {
        *h = V::<2>::new(0.0, self.m * self.g);
    }
    fn constraints(&self, q: &V<2>, _t: f64, phi: &mut V<1>) {
        phi[0] = q[0] * q[0] + q[1] * q[1] - self.l * self.l;
    }
    fn constraint_jacobian(&self, q: &V<2>, _t: f64, j: &mut Mat<1, 2>) {
        *j = Mat::<1, 2>::new(2.0 * q[0], 2.0 * q[1]);
    }
    fn constraint_time_derivative(&self, _q: &V<2>, _t: f64, p: &mut V<1>) {
        p[0] = 0.0;
    }
    fn constraint_rhs(&self, _q: &V<2>, qd: &V<2>, _t: f64, g: &mut V<1>) {
        g[0] = -2.0 * (qd[0] * qd[0] + qd[1] * qd[1]);
    }
    fn actuator_map(&self, b: &mut Mat<2, 1>) {
        *b = Mat::<2, 1>::new(1.0, 0.0);
    }
    fn kinetic_energy(&self, _q: &V<2>, qd: &V<2>, _t: f64) -> f64 {
        0.5 * self.m * qd.norm_squared()
    }
    fn potential_energy(&self, q: &V<2>, _t: f64) -> f64 {
        self.m * self.g * q[1]
    }
}

// ---------------------------------------------------------------------------
// Point mass (x, y, z) held on two unit spheres centred at the origin and at
// (2, 0, 0): they touch at (1, 0, 0), where the two constraint gradients are
// parallel. At (1, d, 0) the Jacobian's condition grows like 1/d^2. Force
// input on y.
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct TouchingSpheres {
    pub m: f64,
    pub g: f64,
}

impl Default for TouchingSpheres {
    fn default() -> Self {
        TouchingSpheres { m: 1.0, g: 9.81 }
    }
}

impl Model<3, 2, 1> for TouchingSpheres {
    const NAME: &'static str = "touching_spheres";
    const COORDINATES: [&'static str; 3] = ["x", "y", "z"];
    const ACTUATORS: [&'static str; 1] = ["fy"];
    fn mass_matrix(&self, _q: &V<3>, _t: f64, m: &mut Mat<3, 3>) {
        *m = Mat::<3, 3>::identity() * self.m;
    }
    fn bias(&self, _q: &V<3>, _qd: &V<3>, _t: f64, h: &mut V<3>) {
        *h = V::<3>::new(0.0, 0.0, self.m * self.g);
    }
    fn constraints(&self, q: &V<3>, _t: f64, phi: &mut V<2>) {
        let c = V::<3>::new(2.0, 0.0, 0.0);
        *phi = V::<2>::new(q.norm_squared() - 1.0, (q - c).norm_squared() - 1.0);
    }
    fn constraint_jacobian(&self, q: &V<3>, _t: f64, j: &mut Mat<2, 3>) {
        j.set_row(0, &(2.0 * q).transpose());
        j.set_row(1, &(2.0 * V::<3>::new(q[0] - 2.0, q[1], q[2])).transpose());
    }
    fn constraint_time_derivative(&self, _q: &V<3>, _t: f64, p: &mut V<2>) {
        *p = V::<2>::zeros();
    }
    fn constraint_rhs(&self, _q: &V<3>, qd: &V<3>, _t: f64, g: &mut V<2>) {
        *g = V::<2>::from_element(-2.0 * qd.norm_squared());
    }
    fn actuator_map(&self, b: &mut Mat<3, 1>) {
        *b = Mat::<3, 1>::new(0.0, 1.0, 0.0);
    }
    fn kinetic_energy(&self, _q: &V<3>, qd: &V<3>, _t: f64) -> f64 {
        0.5 * self.m * qd.norm_squared()
    }
    fn potential_energy(&self, q: &V<3>, _t: f64) -> f64 {
        self.m * self.g * q[2]
    }
}

// ---------------------------------------------------------------------------
// Fault injection around any model.
// ---------------------------------------------------------------------------
#[derive(Clone, Copy, Debug)]
pub struct Faulty<M> {
    pub inner: M,
    /// Multiplies the mass matrix (negative: not positive definite).
    pub mass_scale: f64,
    /// Return NaN in the bias forces.
    pub nan_bias: bool,
    /// Multiplies the bias forces.
    pub bias_scale: f64,
    /// Return a zero actuator map.
    pub zero_actuation: bool,
    /// Return NaN in the actuator map.
    pub nan_actuation: bool,
}

impl<M> Faulty<M> {
    pub fn new(inner: M) -> Self {
        Faulty {
            inner,
            mass_scale: 1.0,
            nan_bias: false,
            bias_scale: 1.0,
            zero_actuation: false,
            nan_actuation: false,
        }
    }
}

impl<M: Model<NQ, NC, NU>, const NQ: usize, const NC: usize, const NU: usize> Model<NQ, NC, NU>
    for Faulty<M>
{
    const NAME: &'static str = "faulty";
    const COORDINATES: [&'static str; NQ] = M::COORDINATES;
    const ACTUATORS: [&'static str; NU] = M::ACTUATORS;
    fn mass_matrix(&self, q: &V<NQ>, t: f64, m: &mut Mat<NQ, NQ>) {
        self.inner.mass_matrix(q, t, m);
        *m *= self.mass_scale;
    }
    fn bias(&self, q: &V<NQ>, qd: &V<NQ>, t: f64, h: &mut V<NQ>) {
        self.inner.bias(q, qd, t, h);
        *h *= self.bias_scale;
        if self.nan_bias && NQ > 0 {
            h[0] = f64::NAN;
        }
    }
    fn constraints(&self, q: &V<NQ>, t: f64, phi: &mut V<NC>) {
        self.inner.constraints(q, t, phi)
    }
    fn constraint_jacobian(&self, q: &V<NQ>, t: f64, j: &mut Mat<NC, NQ>) {
        self.inner.constraint_jacobian(q, t, j)
    }
    fn constraint_time_derivative(&self, q: &V<NQ>, t: f64, p: &mut V<NC>) {
        self.inner.constraint_time_derivative(q, t, p)
    }
    fn constraint_rhs(&self, q: &V<NQ>, qd: &V<NQ>, t: f64, g: &mut V<NC>) {
        self.inner.constraint_rhs(q, qd, t, g)
    }
    fn actuator_map(&self, b: &mut Mat<NQ, NU>) {
        self.inner.actuator_map(b);
        if self.zero_actuation {
            b.fill(0.0);
        }
        if self.nan_actuation {
            b[(0, 0)] = f64::NAN;
        }
    }
    fn kinetic_energy(&self, q: &V<NQ>, qd: &V<NQ>, t: f64) -> f64 {
        self.inner.kinetic_energy(q, qd, t)
    }
    fn potential_energy(&self, q: &V<NQ>, t: f64) -> f64 {
        self.inner.potential_energy(q, t)
    }
}

// ---------------------------------------------------------------------------
// Generic helpers.
// ---------------------------------------------------------------------------

/// Relative deviation of the energy along a sequence: max |E - E0| / |E0|
/// (or absolute if E0 is 0).
pub fn relative_deviation(values: &[f64], e0: f64) -> f64 {
    let scale = if e0 != 0.0 { e0.abs() } else { 1.0 };
    values
        .iter()
        .map(|e| (e - e0).abs() / scale)
        .fold(0.0, f64::max)
}

/// Complete elliptic integral of the first kind K(k) by the arithmetic–
/// geometric mean (independent closed form for the pendulum period).
pub fn elliptic_k(k: f64) -> f64 {
    let (mut a, mut b) = (1.0f64, (1.0 - k * k).sqrt());
    for _ in 0..30 {
        let an = 0.5 * (a + b);
        b = (a * b).sqrt();
        a = an;
    }
    core::f64::consts::PI / (2.0 * a)
}
