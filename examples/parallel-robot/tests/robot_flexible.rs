//! Issue 5: the multi-flexible robot through the robot pipeline (servo
//! inverse dynamics, PD forward runs, the CLI contract) and the checks of the
//! issue: energy of free vibration, the rigid limits (zero modes, stiffness
//! to infinity), and the stiff hard case for the explicit scheme.
//!
//! References are independent of the code under test: the rigid robot's
//! algebraic inverse dynamics (its own generated model), the codegen's
//! symbolic terms evaluated by a separate interpreter, energy conservation,
//! the `1/k` law of a stiff spring's static deflection, and the circle
//! itself. Run in release mode (`cargo test --release -p flexdyn-parallel-robot --test robot_flexible`).

use std::collections::HashMap;
use std::path::Path;

use flexdyn::codegen::{powi_f64, Equations, Graph, Id, Node, Source, Symbol};
use flexdyn::runtime::integrate::{GeneralizedAlpha, StepSettings};
use flexdyn::runtime::nalgebra::{SMatrix, SVector};
use flexdyn::runtime::{
    total_energy, ErrorKind, GeneralizedAlphaConfig, IntegratorOf, Model, Rk4, State,
};
use flexdyn_parallel_robot::robot::{
    flexible_inverse, initial_state, inverse_along, output_times, simulate, Circle, Geometry,
    Layout, Scheme, TorqueTable,
};
use flexdyn_parallel_robot::scenes::parallel_robot_flexible::ParallelRobotFlexible;
use flexdyn_parallel_robot::scenes::parallel_robot_flexible_joints::ParallelRobotFlexibleJoints;
use flexdyn_parallel_robot::scenes::parallel_robot_flexible_links::ParallelRobotFlexibleLinks;
use flexdyn_parallel_robot::scenes::parallel_robot_rigid::ParallelRobotRigid;

const DT: f64 = 0.005;

fn geometry() -> Geometry {
    Geometry::SPEC
}

/// Rigid-robot torques along the paper's circle at `times` (the reference).
fn rigid_torques(omega: f64, times: &[f64]) -> Vec<[f64; 3]> {
    let sols = inverse_along(
        &ParallelRobotRigid,
        &geometry(),
        &Circle::paper(omega),
        times,
        &mut || {},
    )
    .unwrap();
    sols.iter()
        .map(|s| [s.tau[0], s.tau[1], s.tau[2]])
        .collect()
}

fn table(times: &[f64], values: &[[f64; 3]]) -> TorqueTable {
    let samples: Vec<(f64, [f64; 3])> = times.iter().copied().zip(values.iter().copied()).collect();
    TorqueTable::from_samples(&samples).unwrap()
}

/// Largest distance of the platform from the circle over `states`.
fn tracking_error<const NQ: usize>(layout: &Layout, circle: &Circle, states: &[State<NQ>]) -> f64 {
    states
        .iter()
        .map(|s| {
            let want = circle.at(s.t)[0];
            (0..3)
                .map(|k| (s.q[layout.platform[k]] - want[k]).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max)
}

fn max_diff(a: &[[f64; 3]], b: &[[f64; 3]]) -> f64 {
    a.iter()
        .zip(b)
        .flat_map(|(x, y)| (0..3).map(move |i| (x[i] - y[i]).abs()))
        .fold(0.0, f64::max)
}

// ---------------------------------------------------------------------------
// A second evaluator of the generator's symbolic terms: the codegen graph
// compiled to a flat instruction list (independent of the emitter), as a
// runtime `Model`. Used for scene variants that are not compiled in.

enum Op {
    Const(f64),
    Q(usize),
    Qd(usize),
    Time,
    Sum(Vec<(usize, f64)>, f64),
    Prod(Vec<(usize, i32)>),
    Call(flexdyn::codegen::Func, usize),
    Atan2(usize, usize),
}

struct Tape {
    ops: Vec<Op>,
    outputs: Vec<usize>,
}

impl Tape {
    fn new(g: &Graph, roots: &[Id]) -> Tape {
        let order = g.reachable(roots);
        let slot: HashMap<Id, usize> = order.iter().enumerate().map(|(k, &id)| (id, k)).collect();
        let ops = order
            .iter()
            .map(|&id| match g.node(id) {
                Node::Const(c) => Op::Const(c.get()),
                Node::Sym(Symbol::Q(i)) => Op::Q(*i as usize),
                Node::Sym(Symbol::Qd(i)) => Op::Qd(*i as usize),
                Node::Sym(Symbol::Time) => Op::Time,
                Node::Sym(Symbol::Param(_) | Symbol::Qdd(_)) => {
                    panic!("runtime parameters and accelerations are not supported here")
                }
                Node::Sum(ts, k) => Op::Sum(
                    ts.iter().map(|(t, c)| (slot[t], c.get())).collect(),
                    k.get(),
                ),
                Node::Prod(fs) => Op::Prod(fs.iter().map(|(b, e)| (slot[b], *e)).collect()),
                Node::Call(f, a) => Op::Call(*f, slot[a]),
                Node::Atan2(y, x) => Op::Atan2(slot[y], slot[x]),
            })
            .collect();
        Tape {
            ops,
            outputs: roots.iter().map(|r| slot[r]).collect(),
        }
    }

    fn eval(&self, q: &[f64], qd: &[f64], t: f64) -> Vec<f64> {
        let mut v = Vec::with_capacity(self.ops.len());
        for op in &self.ops {
            let x = match op {
                Op::Const(c) => *c,
                Op::Q(i) => q[*i],
                Op::Qd(i) => qd[*i],
                Op::Time => t,
                Op::Sum(ts, k) => ts.iter().fold(*k, |acc, &(s, c)| acc + c * v[s]),
                Op::Prod(fs) => fs
                    .iter()
                    .fold(1.0, |acc, &(s, e)| acc * powi_f64(v[s], e as i64)),
                Op::Call(f, a) => f.apply(v[*a]),
                Op::Atan2(y, x) => f64::atan2(v[*y], v[*x]),
            };
            v.push(x);
        }
        self.outputs.iter().map(|&s| v[s]).collect()
    }
}

/// A scene variant (text) as a runtime model with the coordinates of the
/// compiled model `C`.
struct TapeModel<C, const NQ: usize, const NC: usize> {
    tape: Tape,
    b: SMatrix<f64, NQ, 3>,
    _names: std::marker::PhantomData<C>,
}

impl<C: Model<NQ, NC, 3>, const NQ: usize, const NC: usize> TapeModel<C, NQ, NC> {
    fn from_text(text: &str) -> Self {
        let mut m = flexdyn::codegen::Model::from_source(&Source::new(
            Path::new("variant.toml"),
            text.to_owned(),
        ))
        .unwrap();
        let names: Vec<&str> = m.coordinates.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(
            names,
            C::COORDINATES.to_vec(),
            "variant must keep the coordinates"
        );
        let eq: Equations = m.equations().unwrap();
        assert_eq!(eq.phi.len(), NC);
        let mut roots = Vec::new();
        for i in 0..NQ {
            roots.extend(&eq.mass[i]);
        }
        roots.extend(&eq.bias);
        roots.extend(&eq.phi);
        for r in &eq.phi_q {
            roots.extend(r);
        }
        roots.extend(&eq.phi_t);
        roots.extend(&eq.gamma);
        roots.push(eq.kinetic_energy);
        roots.push(eq.potential_energy);
        let b = SMatrix::from_fn(|i, j| eq.actuator_map[i][j]);
        TapeModel {
            tape: Tape::new(&m.graph, &roots),
            b,
            _names: std::marker::PhantomData,
        }
    }

    fn all(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64) -> Vec<f64> {
        self.tape.eval(q.as_slice(), qd.as_slice(), t)
    }
}

// Offsets into the tape's outputs.
const fn off_h(nq: usize) -> usize {
    nq * nq
}
const fn off_phi(nq: usize) -> usize {
    nq * nq + nq
}

impl<C: Model<NQ, NC, 3>, const NQ: usize, const NC: usize> Model<NQ, NC, 3>
    for TapeModel<C, NQ, NC>
{
    const NAME: &'static str = "tape_variant";
    const COORDINATES: [&'static str; NQ] = C::COORDINATES;
    const ACTUATORS: [&'static str; 3] = C::ACTUATORS;

    fn mass_matrix(&self, q: &SVector<f64, NQ>, t: f64, m: &mut SMatrix<f64, NQ, NQ>) {
        let v = self.all(q, q, t);
        *m = SMatrix::from_fn(|i, j| v[i * NQ + j]);
    }
    fn bias(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64, h: &mut SVector<f64, NQ>) {
        let v = self.all(q, qd, t);
        *h = SVector::from_fn(|i, _| v[off_h(NQ) + i]);
    }
    fn constraints(&self, q: &SVector<f64, NQ>, t: f64, phi: &mut SVector<f64, NC>) {
        let v = self.all(q, q, t);
        *phi = SVector::from_fn(|i, _| v[off_phi(NQ) + i]);
    }
    fn constraint_jacobian(&self, q: &SVector<f64, NQ>, t: f64, phi_q: &mut SMatrix<f64, NC, NQ>) {
        let v = self.all(q, q, t);
        *phi_q = SMatrix::from_fn(|i, j| v[off_phi(NQ) + NC + i * NQ + j]);
    }
    fn constraint_time_derivative(&self, q: &SVector<f64, NQ>, t: f64, p: &mut SVector<f64, NC>) {
        let v = self.all(q, q, t);
        *p = SVector::from_fn(|i, _| v[off_phi(NQ) + NC + NC * NQ + i]);
    }
    fn constraint_rhs(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        gamma: &mut SVector<f64, NC>,
    ) {
        let v = self.all(q, qd, t);
        *gamma = SVector::from_fn(|i, _| v[off_phi(NQ) + 2 * NC + NC * NQ + i]);
    }
    fn actuator_map(&self, b: &mut SMatrix<f64, NQ, 3>) {
        *b = self.b;
    }
    fn kinetic_energy(&self, q: &SVector<f64, NQ>, qd: &SVector<f64, NQ>, t: f64) -> f64 {
        let v = self.all(q, qd, t);
        v[v.len() - 2]
    }
    fn potential_energy(&self, q: &SVector<f64, NQ>, t: f64) -> f64 {
        let v = self.all(q, q, t);
        v[v.len() - 1]
    }
    fn dynamics_terms(
        &self,
        q: &SVector<f64, NQ>,
        qd: &SVector<f64, NQ>,
        t: f64,
        m: &mut SMatrix<f64, NQ, NQ>,
        h: &mut SVector<f64, NQ>,
        phi_q: &mut SMatrix<f64, NC, NQ>,
        gamma: &mut SVector<f64, NC>,
    ) {
        let v = self.all(q, qd, t);
        *m = SMatrix::from_fn(|i, j| v[i * NQ + j]);
        *h = SVector::from_fn(|i, _| v[off_h(NQ) + i]);
        *phi_q = SMatrix::from_fn(|i, j| v[off_phi(NQ) + NC + i * NQ + j]);
        *gamma = SVector::from_fn(|i, _| v[off_phi(NQ) + 2 * NC + NC * NQ + i]);
    }
}

fn scene_text(name: &str) -> String {
    std::fs::read_to_string(format!("{}/scenes/{name}.toml", env!("CARGO_MANIFEST_DIR"))).unwrap()
}

/// Deterministic pseudo-random numbers in `[-1, 1)` (xorshift).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

// ---------------------------------------------------------------------------

#[test]
fn tape_evaluator_agrees_with_the_compiled_scene() {
    // Guards the reference evaluator used below: same scene, two evaluators.
    let tape: TapeModel<ParallelRobotFlexibleLinks, 33, 12> =
        TapeModel::from_text(&scene_text("parallel_robot_flexible_links"));
    let model = ParallelRobotFlexibleLinks;
    let mut rng = Rng(3);
    for _ in 0..5 {
        let q = SVector::<f64, 33>::from_fn(|_, _| 0.5 * rng.next());
        let qd = SVector::<f64, 33>::from_fn(|_, _| rng.next());
        let (mut m1, mut m2) = (SMatrix::zeros(), SMatrix::zeros());
        let (mut h1, mut h2) = (SVector::zeros(), SVector::zeros());
        let (mut j1, mut j2) = (SMatrix::zeros(), SMatrix::zeros());
        let (mut g1, mut g2) = (SVector::zeros(), SVector::zeros());
        model.dynamics_terms(&q, &qd, 0.0, &mut m1, &mut h1, &mut j1, &mut g1);
        tape.dynamics_terms(&q, &qd, 0.0, &mut m2, &mut h2, &mut j2, &mut g2);
        assert!((m1 - m2).amax() <= 1e-9 * m1.amax(), "mass matrix");
        assert!((h1 - h2).amax() <= 1e-9 * h1.amax().max(1.0), "bias");
        assert!((j1 - j2).amax() <= 1e-12 * j1.amax().max(1.0), "jacobian");
        assert!((g1 - g2).amax() <= 1e-9 * g1.amax().max(1.0), "gamma");
    }
}

#[test]
fn zero_modes_reduce_the_flexible_link_robot_to_the_rigid_one() {
    // The flexible-links scene with no modes kept, against the rigid scene:
    // on the rigid robot's twelve coordinates (platform rotations zero and at
    // rest) the mass matrix, the bias forces and both energies are the same.
    let text = scene_text("parallel_robot_flexible_links").replace("modes = 6", "modes = 0");
    let load = |t: &str| {
        flexdyn::codegen::Model::from_source(&Source::new(Path::new("s.toml"), t.to_owned()))
            .unwrap()
    };
    let mut mf = load(&text);
    let mut mr = load(&scene_text("parallel_robot_rigid"));
    assert_eq!(mf.nq(), 15, "12 rigid coordinates and 3 platform rotations");
    let ef = mf.equations().unwrap();
    let er = mr.equations().unwrap();
    let idx: Vec<usize> = flexdyn_parallel_robot::robot::RIGID_COORDINATES
        .iter()
        .map(|n| {
            mf.coordinates
                .iter()
                .position(|c| c.name.as_str() == *n)
                .unwrap()
        })
        .collect();
    let mut rng = Rng(11);
    for _ in 0..20 {
        // A rigid pose on the circle's neighbourhood with random rates.
        let p = [0.1 * rng.next(), 0.1 * rng.next(), 0.7 + 0.05 * rng.next()];
        let qr = flexdyn_parallel_robot::robot::inverse_kinematics(&geometry(), p).unwrap();
        let qdr: Vec<f64> = (0..12).map(|_| rng.next()).collect();
        let (mut qf, mut qdf) = (vec![0.0; 15], vec![0.0; 15]);
        for k in 0..12 {
            qf[idx[k]] = qr[k];
            qdf[idx[k]] = qdr[k];
        }
        let env_f = |s: Symbol| match s {
            Symbol::Q(i) => qf[i as usize],
            Symbol::Qd(i) => qdf[i as usize],
            _ => 0.0,
        };
        let env_r = |s: Symbol| match s {
            Symbol::Q(i) => qr[i as usize],
            Symbol::Qd(i) => qdr[i as usize],
            _ => 0.0,
        };
        let ef_v = mf
            .graph
            .eval(&[ef.kinetic_energy, ef.potential_energy], &env_f);
        let er_v = mr
            .graph
            .eval(&[er.kinetic_energy, er.potential_energy], &env_r);
        for k in 0..2 {
            assert!(
                (ef_v[k] - er_v[k]).abs() <= 1e-12 * er_v[k].abs().max(1.0),
                "energy {k}"
            );
        }
        let hf = mf.graph.eval(&ef.bias, &env_f);
        let hr = mr.graph.eval(&er.bias, &env_r);
        for a in 0..12 {
            assert!(
                (hf[idx[a]] - hr[a]).abs() <= 1e-10 * hr[a].abs().max(1.0),
                "bias {a}: {} vs {}",
                hf[idx[a]],
                hr[a]
            );
            let rowf = mf.graph.eval(&ef.mass[idx[a]], &env_f);
            let rowr = mr.graph.eval(&er.mass[a], &env_r);
            for b in 0..12 {
                assert!((rowf[idx[b]] - rowr[b]).abs() <= 1e-12 * rowr[b].abs().max(1.0));
            }
        }
    }
}

/// Servo-constraint torques of a model along the circle at `omega`.
fn servo_torques<M, const NQ: usize, const NC: usize>(
    model: &M,
    omega: f64,
    times: &[f64],
) -> (Vec<[f64; 3]>, Vec<State<NQ>>)
where
    M: Model<NQ, NC, 3>,
{
    let layout = Layout::of(model).unwrap();
    let samples = flexible_inverse(
        model,
        &layout,
        &geometry(),
        &Circle::paper(omega),
        times,
        &mut || {},
    )
    .unwrap();
    (
        samples.iter().map(|s| s.tau.into()).collect(),
        samples.iter().map(|s| s.state).collect(),
    )
}

#[test]
fn servo_inverse_dynamics_of_the_rigid_scene_is_the_rigid_inverse_dynamics() {
    // The servo path run on the rigid scene must give its algebraic torques.
    let times = output_times(0.5, DT, flexdyn::steps::MAX_STEPS).unwrap();
    let layout = Layout::of(&ParallelRobotRigid).unwrap();
    let samples = flexible_inverse(
        &ParallelRobotRigid,
        &layout,
        &geometry(),
        &Circle::paper(2.0),
        &times,
        &mut || {},
    )
    .unwrap();
    let servo: Vec<[f64; 3]> = samples.iter().map(|s| s.tau.into()).collect();
    let d = max_diff(&servo, &rigid_torques(2.0, &times));
    // The servo run integrates the motion (generalized-alpha, 0.005 s) where the
    // algebraic solve is exact at each time: they agree to the integration
    // error, five orders of magnitude below the torques (about 18 N m).
    println!("servo vs algebraic rigid torques: {d:.3e} N m");
    assert!(
        d < 1e-3,
        "servo vs algebraic rigid torques differ by {d} N m"
    );
}

#[test]
fn flexible_torques_track_the_circle_open_loop_better_than_rigid_ones() {
    // Issue 5's criterion. Torques from the servo run at the paper's step,
    // replayed open loop at a five times finer step (linearly interpolated),
    // against the rigid model's torques replayed the same way. The open-loop
    // robot is unstable (a few mm of error grow to metres within seconds), so
    // both are measured over the first 0.5 s.
    let times = output_times(0.5, DT, flexdyn::steps::MAX_STEPS).unwrap();
    let model = ParallelRobotFlexible::default();
    let layout = Layout::of(&model).unwrap();
    let circle = Circle::paper(2.0);
    let (flex, servo_states) = servo_torques(&model, 2.0, &times);
    let servo_error = tracking_error(&layout, &circle, &servo_states);
    assert!(
        servo_error < 1e-5,
        "servo run left the circle by {servo_error} m"
    );
    let rigid = rigid_torques(2.0, &times);
    let [p, v, _] = circle.at(0.0);
    let replay = |tau: &[[f64; 3]]| {
        let start = initial_state(&model, &layout, &geometry(), 0.0, p, v).unwrap();
        let states = simulate(
            ("parallel_robot_flexible", &model),
            Scheme::GeneralizedAlpha,
            start,
            &table(&times, tau),
            0.001,
            500,
            1,
            &mut || {},
        )
        .unwrap();
        tracking_error(&layout, &circle, &states)
    };
    let (a, b) = (replay(&rigid), replay(&flex));
    println!(
        "open-loop tracking error over 0.5 s: rigid torques {a:.3e} m, flexible torques {b:.3e} m"
    );
    assert!(
        a > 1e-3,
        "the rigid torques should visibly miss the flexible robot's path: {a}"
    );
    assert!(
        b < a / 20.0,
        "flexible torques {b} m should track far better than rigid {a} m"
    );
}

/// First sample compared in the limit tests, 0.25 s: after the start-up
/// transient (the runs start at the static equilibrium under gravity, not
/// under the inertial loads of the moving start; the servo's stabilisation
/// settles the difference with a time constant of 0.1 s).
const SETTLED: usize = 50;

/// The PD loop of the scenes around the rigid robot's joint angles.
fn pd_settings(circle: &Circle, times: &[f64]) -> flexdyn_parallel_robot::robot::PdSettings {
    let sols = inverse_along(&ParallelRobotRigid, &geometry(), circle, times, &mut || {}).unwrap();
    let th: Vec<[f64; 3]> = sols.iter().map(|s| [s.q[0], s.q[3], s.q[6]]).collect();
    flexdyn_parallel_robot::robot::PdSettings {
        kp: 2000.0,
        kd: 40.0,
        reference: table(times, &th),
    }
}

/// The platform path under the rigid torques plus the PD loop,
/// generalized-alpha at the paper's step.
fn pd_path<M, const NQ: usize, const NC: usize>(model: &M, times: &[f64]) -> Vec<[f64; 3]>
where
    M: Model<NQ, NC, 3>,
{
    let circle = Circle::paper(2.0);
    let [p, v, _] = circle.at(0.0);
    let rows = flexdyn_parallel_robot::robot::simulate_rows(
        model,
        &geometry(),
        Scheme::GeneralizedAlpha,
        (0.0, p, v),
        &table(times, &rigid_torques(2.0, times)),
        Some(&pd_settings(&circle, times)),
        (DT, times.len() - 1, 1),
        &mut || {},
    )
    .unwrap();
    rows.iter().map(|r| r.p).collect()
}

#[test]
fn stiffer_links_converge_to_the_rigid_robot() {
    // E scaled up 10^4 (a generation-time constant: the variant is derived here
    // and evaluated by the tape): the servo torques, and the path under the
    // rigid torques with the PD loop, approach the rigid robot's much closer
    // than with the nominal links.
    // The rigid reference through the same servo path, so that its
    // integration error (about 1e-4 N m) cancels.
    let times = output_times(0.5, DT, flexdyn::steps::MAX_STEPS).unwrap();
    let rigid = servo_torques(&ParallelRobotRigid, 2.0, &times).0;
    let text = scene_text("parallel_robot_flexible_links");
    assert!(text.contains("E3 = 2.07e11"));
    let stiff: TapeModel<ParallelRobotFlexibleLinks, 33, 12> =
        TapeModel::from_text(&text.replace("E3 = 2.07e11", "E3 = 2.07e15"));
    let stiffer: TapeModel<ParallelRobotFlexibleLinks, 33, 12> =
        TapeModel::from_text(&text.replace("E3 = 2.07e11", "E3 = 2.07e13"));
    let nominal_tau = servo_torques(&ParallelRobotFlexibleLinks, 2.0, &times).0;
    let stiffer_tau = servo_torques(&stiffer, 2.0, &times).0;
    let stiff_tau = servo_torques(&stiff, 2.0, &times).0;
    let (d_nominal, d_stiffer, d_stiff) = (
        max_diff(&nominal_tau[SETTLED..], &rigid[SETTLED..]),
        max_diff(&stiffer_tau[SETTLED..], &rigid[SETTLED..]),
        max_diff(&stiff_tau[SETTLED..], &rigid[SETTLED..]),
    );
    println!(
        "max |tau - tau_rigid|: nominal E {d_nominal:.3e} N m, E x 1e2 {d_stiffer:.3e} N m, \
         E x 1e4 {d_stiff:.3e} N m"
    );
    assert!(
        d_nominal > 1e-5,
        "the nominal links should differ visibly: {d_nominal}"
    );
    // The elastic correction scales as 1 / E: 100x stiffer links bring the
    // torques at least 20x closer (measured 57x); beyond that the servo
    // integration's own error (about 5e-7 N m here) is the floor.
    assert!(
        d_stiffer < d_nominal / 20.0 && d_stiff < d_nominal / 20.0,
        "{d_stiffer}, {d_stiff} vs {d_nominal}"
    );
    // Path: the rigid torques plus the PD loop, compared after the loop has
    // settled the start (the runs start at the static equilibrium, not at the
    // rigid robot's, so they begin a few micrometres apart).
    let rigid_path = pd_path(&ParallelRobotRigid, &times);
    let off = |path: Vec<[f64; 3]>| max_diff(&path[SETTLED..], &rigid_path[SETTLED..]);
    let dev_nominal = off(pd_path(&ParallelRobotFlexibleLinks, &times));
    let dev_stiff = off(pd_path(&stiff, &times));
    println!(
        "max |p - p_rigid| after 0.25 s: nominal E {dev_nominal:.3e} m, E x 1e4 {dev_stiff:.3e} m"
    );
    // The path deviation is a static deflection, also 1 / E: at least 100x
    // smaller at E x 1e4 (measured 315x).
    assert!(
        dev_stiff < dev_nominal / 100.0,
        "{dev_stiff} vs {dev_nominal}"
    );
}

#[test]
fn stiffer_joints_converge_to_the_rigid_robot_carrying_the_joint_members() {
    // As kj1, kj2 (runtime parameters) grow, the flexible-joints robot tends
    // to the rigid robot carrying the six joint members (0.07 kg each, at c_i
    // and at p_i), which the rigid model of the spec leaves out. Reference:
    // the rigid scene with those point masses added, derived here and
    // evaluated by the tape (the members' rotor inertias, below 2e-5 kg m^2,
    // are left out of the reference). Both through the same servo path, so
    // that its integration error (about 1e-4 N m) cancels.
    let times = output_times(0.5, DT, flexdyn::steps::MAX_STEPS).unwrap();
    let mut text = scene_text("parallel_robot_rigid");
    assert!(text.contains("mp = 2.6 "));
    // Three members at p_i move with the translating platform.
    text = text.replace("mp = 2.6 ", "mp = 2.81 ");
    for i in 1..=3 {
        text.push_str(&format!(
            "\n[[components]]\nname = \"member{i}\"\ntype = \"rigid_body\"\nmass = 0.07\n\
             frame = \"knee{i}\"\ninertia = [[1e-9, 0, 0], [0, 1e-9, 0], [0, 0, 1e-9]]\n"
        ));
    }
    let reference: TapeModel<ParallelRobotRigid, 12, 9> = TapeModel::from_text(&text);
    let want = servo_torques(&reference, 2.0, &times).0;
    let rigid = servo_torques(&ParallelRobotRigid, 2.0, &times).0;
    let d_members = max_diff(&want[SETTLED..], &rigid[SETTLED..]);
    for scale in [1.0, 100.0, 1e4] {
        let mut m = ParallelRobotFlexibleJoints::default();
        assert!(m.set_parameter("kj1", m.kj1 * scale) && m.set_parameter("kj2", m.kj2 * scale));
        let got = servo_torques(&m, 2.0, &times).0;
        let d = max_diff(&got[SETTLED..], &want[SETTLED..]);
        println!(
            "kj x {scale:e}: max |tau - tau_limit| = {d:.3e} N m (the members alone: {d_members:.3e} N m)"
        );
        assert!(d < 2e-3 && d < d_members / 100.0, "{d} vs {d_members}");
    }
}

#[test]
fn free_vibration_conserves_energy_with_the_implicit_scheme() {
    // No input torque, no damping (the scene has none), gravity on. With the
    // actuated joints free the robot falls through its workspace (checked at
    // the end for as long as it stays regular), so for 5 s the actuators
    // hold it as brakes: linear torsion springs (the PD gain kp, no
    // damping) at the start angles, whose energy 1/2 kp (th - th0)^2 is
    // counted. From rest (static equilibrium, no torque on the springs yet) it sags and swings on those
    // springs (about 10 Hz) while its elastic coordinates vibrate.
    // Generalized-alpha with rho_inf = 1 (trapezoidal: no numerical
    // dissipation), 0.005 s, 5 s, coordinate projection after every step.
    // Tolerance: T + V + spring energy within 1e-6 of the mechanism's energy
    // scale m g h (about 99 J), i.e. 0.1 mJ (measured: 2e-5 J; with the
    // dissipative rho_inf = 0.8 the drift is far larger).
    let model = ParallelRobotFlexible::default();
    let layout = Layout::of(&model).unwrap();
    let mut state =
        initial_state(&model, &layout, &geometry(), 0.0, [0.0, 0.0, 0.7], [0.0; 3]).unwrap();
    let kp = 2000.0;
    let th0 = layout.actuated.map(|i| state.q[i]);
    let held = flexdyn::runtime::control::Feedback {
        inner: &model,
        law: |q: &SVector<f64, 39>, _: &SVector<f64, 39>, _: f64| -> SVector<f64, 3> {
            SVector::from_fn(|j, _| kp * (th0[j] - q[layout.actuated[j]]))
        },
    };
    let energy = |s: &State<39>| {
        total_energy(&model, s)
            + (0..3)
                .map(|j| 0.5 * kp * (s.q[layout.actuated[j]] - th0[j]).powi(2))
                .sum::<f64>()
    };
    let config = GeneralizedAlphaConfig {
        rho_inf: 1.0,
        ..Default::default()
    };
    let mut integ = GeneralizedAlpha::<39, 12>::new(StepSettings::with_projection(), config);
    let e0 = energy(&state);
    let zero = SVector::<f64, 3>::zeros();
    let (mut worst, mut swing, mut kinetic): (f64, f64, f64) = (0.0, 0.0, 0.0);
    for _ in 0..1000 {
        integ.step(&held, &mut state, &zero, DT).unwrap();
        worst = worst.max((energy(&state) - e0).abs());
        swing = swing.max((state.q[layout.platform[2]] - 0.7).abs());
        kinetic = kinetic.max(model.kinetic_energy(&state.q, &state.qd, state.t));
    }
    let scale = 9.81 * 0.7 * (3.0 * (2.0 + 0.3 + 1.5 + 0.14) + 2.6);
    println!(
        "energy drift over 5 s: {worst:.3e} J (scale {scale:.1} J, peak kinetic {kinetic:.3e} J); \
         platform swing {swing:.3e} m"
    );
    assert!(swing > 1e-3, "the robot should sag and swing: {swing}");
    assert!(kinetic > 1e-3, "{kinetic}");
    assert!(worst < 1e-6 * scale, "energy drift {worst} J");

    // Literally zero torques: released from the same rest pose the robot
    // falls, and folds into a singular pose after 0.85 s (measured with
    // `parallel-robot simulate` and zero torques). Over its first 0.75 s the motion
    // is large and fast (kinetic energy up to about 45 J), so the
    // trapezoidal rule conserves T + V only to its second-order error:
    // stated tolerance 1e-3 of the scale at the paper's step, and the drift
    // must shrink at least 3x per halving of the step.
    let fall = |dt: f64| {
        let mut state =
            initial_state(&model, &layout, &geometry(), 0.0, [0.0, 0.0, 0.7], [0.0; 3]).unwrap();
        let mut integ = GeneralizedAlpha::<39, 12>::new(StepSettings::with_projection(), config);
        let e0 = total_energy(&model, &state);
        let (mut worst, mut kinetic): (f64, f64) = (0.0, 0.0);
        for _ in 0..(0.75 / dt).round() as usize {
            integ.step(&model, &mut state, &zero, dt).unwrap();
            worst = worst.max((total_energy(&model, &state) - e0).abs());
            kinetic = kinetic.max(model.kinetic_energy(&state.q, &state.qd, state.t));
        }
        (worst, kinetic)
    };
    let drifts: Vec<(f64, f64)> = [DT, DT / 2.0, DT / 4.0]
        .iter()
        .map(|&dt| fall(dt))
        .collect();
    for (dt, (drift, kinetic)) in [DT, DT / 2.0, DT / 4.0].iter().zip(&drifts) {
        println!("zero torques, 0.75 s of falling at {dt} s: energy drift {drift:.3e} J, peak kinetic {kinetic:.3e} J");
    }
    assert!(drifts[0].1 > 10.0, "the robot should fall: {drifts:?}");
    assert!(drifts[0].0 < 1e-3 * scale, "{drifts:?}");
    assert!(
        drifts[0].0 > 3.0 * drifts[1].0 && drifts[1].0 > 3.0 * drifts[2].0,
        "{drifts:?}"
    );
}

#[test]
fn explicit_rk4_is_reported_unstable_and_the_implicit_scheme_is_not() {
    // The stiff hard case: the flexible robot at the paper's 0.005 s step.
    let model = ParallelRobotFlexible::default();
    let layout = Layout::of(&model).unwrap();
    let circle = Circle::paper(2.0);
    let [p, v, _] = circle.at(0.0);
    let start = initial_state(&model, &layout, &geometry(), 0.0, p, v).unwrap();
    let times = output_times(5.0, DT, flexdyn::steps::MAX_STEPS).unwrap();
    let tau = table(&times, &rigid_torques(2.0, &times));
    // The runtime's own error, not NaN output.
    let mut rk4 = Rk4::new(StepSettings::default());
    let mut s = start;
    let input = flexdyn::runtime::FromFn(|t: f64| SVector::<f64, 3>::from(tau.at(t)));
    let err = rk4.step(&model, &mut s, &input, DT).unwrap_err();
    assert!(matches!(err.kind, ErrorKind::StepTooLarge { .. }), "{err}");
    assert_eq!(s, start, "the state is left as it was");
    // Through the pipeline the message says what to do.
    let msg = simulate(
        ("parallel_robot_flexible", &model),
        Scheme::Rk4,
        start,
        &tau,
        DT,
        10,
        1,
        &mut || {},
    )
    .unwrap_err();
    assert!(
        msg.contains("unstable") && msg.contains("gen-alpha"),
        "{msg}"
    );
    // The implicit scheme runs the 5 s under the rigid torques and the PD
    // loop, stays bounded, and agrees with a five times finer step.
    let pd = pd_settings(&circle, &times);
    let run = |dt: f64, steps: usize, every: usize| {
        flexdyn_parallel_robot::robot::simulate_rows(
            &model,
            &geometry(),
            Scheme::GeneralizedAlpha,
            (0.0, p, v),
            &tau,
            Some(&pd),
            (dt, steps, every),
            &mut || {},
        )
        .unwrap()
    };
    let coarse = run(DT, 1000, 1);
    let fine = run(0.001, 5000, 5);
    assert_eq!(coarse.len(), fine.len());
    let dev = |r: &flexdyn_parallel_robot::robot::SimRow| {
        let want = circle.at(r.t)[0];
        [r.p[0] - want[0], r.p[1] - want[1], r.p[2] - want[2]]
    };
    let (mut worst, mut diff): (f64, f64) = (0.0, 0.0);
    for (c, f) in coarse.iter().zip(&fine) {
        assert!((c.t - f.t).abs() < 1e-9);
        let (dc, df) = (dev(c), dev(f));
        for k in 0..3 {
            assert!(dc[k].is_finite());
            worst = worst.max(dc[k].abs());
            if c.t > 0.5 {
                diff = diff.max((dc[k] - df[k]).abs());
            }
        }
    }
    println!("PD run: max deviation {worst:.3e} m; dt 0.005 vs 0.001 after 0.5 s: {diff:.3e} m");
    assert!(worst < 1e-3, "{worst}");
    assert!(diff < 0.1 * worst, "{diff} vs {worst}");
}

fn flexdyn(args: &[&str]) -> (bool, String) {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_parallel-robot"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("run flexdyn");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn cli_contract_holds_for_the_flexible_scenes() {
    use flexdyn::table::Table;
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n).to_string_lossy().into_owned();
    let (rigid, flex, sim, png) = (p("rigid.csv"), p("flex.csv"), p("sim.csv"), p("dev.png"));
    let (ok, err) = flexdyn(&[
        "inverse",
        "--scene",
        "scenes/parallel_robot_rigid.toml",
        "--duration",
        "0.25",
        "--csv",
        &rigid,
        "--quiet",
    ]);
    assert!(ok, "{err}");
    let (ok, err) = flexdyn(&[
        "inverse",
        "--scene",
        "scenes/parallel_robot_flexible.toml",
        "--duration",
        "0.25",
        "--csv",
        &flex,
        "--plot",
        &png,
        "--quiet",
    ]);
    assert!(ok, "{err}");
    let t = Table::read(Path::new(&flex)).unwrap();
    for c in [
        "t", "tau_1", "tau_2", "tau_3", "px", "py", "pz", "th11", "dx", "dy", "dz",
    ] {
        assert!(
            t.columns.iter().any(|x| x == c),
            "inverse: missing column {c}"
        );
    }
    assert_eq!(t.rows.len(), 51);
    for k in ["dx", "dy", "dz"] {
        assert!(
            t.column(k).unwrap().iter().all(|d| d.abs() < 1e-5),
            "servo left the circle"
        );
    }
    for scene in [
        "scenes/parallel_robot_flexible.toml",
        "scenes/parallel_robot_flexible_links.toml",
        "scenes/parallel_robot_flexible_joints.toml",
        "scenes/parallel_robot_soft.toml",
    ] {
        let (ok, err) = flexdyn(&[
            "simulate",
            "--scene",
            scene,
            "--torques",
            &rigid,
            "--dt",
            "0.005",
            "--pd",
            "--csv",
            &sim,
            "--plot",
            &png,
            "--quiet",
        ]);
        assert!(ok, "{scene}: {err}");
        let t = Table::read(Path::new(&sim)).unwrap();
        for c in [
            "t", "tau_1", "tau_2", "tau_3", "px", "py", "pz", "dx", "dy", "dz", "phi_max",
        ] {
            assert!(
                t.columns.iter().any(|x| x == c),
                "simulate: missing column {c}"
            );
        }
        let dz = t.column("dz").unwrap();
        assert!(
            dz.iter().all(|d| d.is_finite() && d.abs() < 5e-3),
            "{scene}: {dz:?}"
        );
        assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
    }
    // The explicit scheme at the paper's step: a clear error, no output.
    let never = p("never.csv");
    let (ok, err) = flexdyn(&[
        "simulate",
        "--scene",
        "scenes/parallel_robot_flexible.toml",
        "--torques",
        &rigid,
        "--dt",
        "0.005",
        "--integrator",
        "rk4",
        "--csv",
        &never,
        "--quiet",
    ]);
    assert!(
        !ok && err.contains("unstable") && !err.contains("panicked"),
        "{err}"
    );
    assert!(!Path::new(&never).exists());
    // --pd needs the reference angles and sane gains.
    let bare = p("bare.csv");
    std::fs::write(
        &bare,
        "t,tau_1,tau_2,tau_3,px,py,pz\n0,1,2,3,0.1,0,0.7\n0.1,1,2,3,0.1,0,0.7\n",
    )
    .unwrap();
    let (ok, err) = flexdyn(&[
        "simulate",
        "--scene",
        "scenes/parallel_robot_flexible.toml",
        "--torques",
        &bare,
        "--pd",
    ]);
    assert!(!ok && err.contains("no column `th11`"), "{err}");
    let (ok, err) = flexdyn(&[
        "simulate",
        "--scene",
        "scenes/parallel_robot_flexible.toml",
        "--torques",
        &rigid,
        "--kp",
        "-5",
    ]);
    assert!(
        !ok && err.contains("invalid PD gain: proportional gain kp (finite, >= 0) = -5"),
        "{err}"
    );
}
