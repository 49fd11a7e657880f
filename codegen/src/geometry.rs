//! Symbolic 3-vectors and rotations on the expression graph: dot and cross
//! products, rotation matrices (Rodrigues' formula about a unit axis),
//! their products, and frames (pose and velocities) built by translating and
//! rotating a parent frame. Velocities are kept in each frame's own axes.

use crate::expr::{Graph, Id};

/// World-frame pose of a frame, with the velocity of its origin and its
/// angular velocity both in the frame's own axes. Keeping velocities in local
/// axes means constant rotations (a chain placed at 120 degrees) never enter
/// the kinetic energy, which stays as simple as the mechanism.
#[derive(Debug, Clone)]
pub(crate) struct Frame {
    /// Rotation from the frame's axes to world axes.
    pub(crate) rotation: [[Id; 3]; 3],
    /// Origin in world coordinates.
    pub(crate) origin: [Id; 3],
    /// Velocity of the origin in the frame's own axes.
    pub(crate) velocity: [Id; 3],
    /// Angular velocity in the frame's own axes.
    pub(crate) omega: [Id; 3],
    /// How the frame is placed from the world, step by step, for its
    /// velocities in world axes ([`Graph::world_velocities`]), which only
    /// markers need: kept as steps so that scenes without markers build
    /// no nodes for them.
    pub(crate) steps: Vec<Step>,
    /// Its index in the model's kinematic tree (`Model::placements`);
    /// `None` for the world.
    pub(crate) node: Option<usize>,
}

/// One step of a frame's placement, with the world rotation before it.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Step {
    /// A translation, `local` in the axes `rotation`, `offset` in world axes.
    Translate {
        rotation: [[Id; 3]; 3],
        local: [Id; 3],
        offset: [Id; 3],
    },
    /// A rotation by `angle` about the unit `axis` of the axes `rotation`.
    Rotate {
        rotation: [[Id; 3]; 3],
        axis: [f64; 3],
        angle: Id,
    },
}

/// A material point: world position, and velocity in the axes of the frame
/// it was given in (all points of one component share those axes).
pub(crate) struct Point {
    /// World position.
    pub(crate) position: [Id; 3],
    /// Velocity in the axes of the frame it was given in.
    pub(crate) velocity: [Id; 3],
    /// That frame's node in the kinematic tree (`None` for the world).
    pub(crate) node: Option<usize>,
    /// The point in that frame's axes, from its origin.
    pub(crate) local: [Id; 3],
}

/// A point's velocities in world axes ([`Graph::world_velocities`]).
pub(crate) struct WorldVelocities {
    /// Angular velocity of its frame.
    pub(crate) angular: [Id; 3],
    /// Its linear velocity, summed across the translations.
    pub(crate) linear: [Id; 3],
    /// The same velocity written about the point, for the Jacobian.
    pub(crate) linear_about_point: [Id; 3],
}

/// Vector and frame operations of the model stage, as graph methods.
impl Graph {
    /// `a . b`.
    pub(crate) fn dot(&mut self, a: [Id; 3], b: [Id; 3]) -> Id {
        let terms: Vec<Id> = (0..3).map(|k| self.mul(a[k], b[k])).collect();
        self.sum(&terms)
    }

    /// `a x b`.
    pub(crate) fn cross(&mut self, a: [Id; 3], b: [Id; 3]) -> [Id; 3] {
        std::array::from_fn(|k| {
            let (i, j) = ((k + 1) % 3, (k + 2) % 3);
            let p = self.mul(a[i], b[j]);
            let q = self.mul(a[j], b[i]);
            self.sub(p, q)
        })
    }

    /// `R v`.
    pub(crate) fn rotate(&mut self, r: &[[Id; 3]; 3], v: [Id; 3]) -> [Id; 3] {
        std::array::from_fn(|i| self.row_dot(r[i], v))
    }

    /// `R^T v`.
    pub(crate) fn rotate_transpose(&mut self, r: &[[Id; 3]; 3], v: [Id; 3]) -> [Id; 3] {
        std::array::from_fn(|i| self.row_dot([r[0][i], r[1][i], r[2][i]], v))
    }

    /// `a . v`, numeric entries of `a` as the coefficients of one sum (which
    /// keeps the sums of more than two terms it scales as terms, see
    /// `SCALED_MAX_TERMS` in [`crate::expr`]: a tilt's three rows would
    /// otherwise repeat every term of the vector's components; measured on
    /// the Unitree G1's inverse dynamics, with its shoulders tilted, 5,983
    /// operations opened, 5,038 kept).
    fn row_dot(&mut self, a: [Id; 3], v: [Id; 3]) -> Id {
        let mut terms: Vec<(Id, f64)> = Vec::with_capacity(3);
        for k in 0..3 {
            match self.as_const(a[k]) {
                Some(c) => terms.push((v[k], c)),
                None => {
                    let p = self.mul(a[k], v[k]);
                    terms.push((p, 1.0));
                }
            }
        }
        self.linear(&terms, 0.0)
    }

    /// `A B`.
    pub(crate) fn matmul(&mut self, a: &[[Id; 3]; 3], b: &[[Id; 3]; 3]) -> [[Id; 3]; 3] {
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                let terms: Vec<Id> = (0..3).map(|k| self.mul(a[i][k], b[k][j])).collect();
                self.sum(&terms)
            })
        })
    }

    /// Rotation by `angle` about the unit vector `u` (Rodrigues).
    pub(crate) fn axis_rotation(&mut self, u: [f64; 3], angle: Id) -> [[Id; 3]; 3] {
        let c = self.cos(angle);
        let s = self.sin(angle);
        std::array::from_fn(|i| {
            std::array::from_fn(|j| {
                // R = c I + s [u]x + (1 - c) u u^T
                let uu = u[i] * u[j];
                let cross = match (i, j) {
                    (0, 1) => -u[2],
                    (1, 0) => u[2],
                    (0, 2) => u[1],
                    (2, 0) => -u[1],
                    (1, 2) => -u[0],
                    (2, 1) => u[0],
                    _ => 0.0,
                };
                let diag = if i == j { 1.0 } else { 0.0 };
                // (diag - uu) c + cross s + uu
                self.linear(&[(c, diag - uu), (s, cross)], uu)
            })
        })
    }

    /// The world frame: identity axes, at rest.
    pub(crate) fn world_frame(&mut self) -> Frame {
        let zero = self.constant(0.0);
        let one = self.constant(1.0);
        let mut rotation = [[zero; 3]; 3];
        for (k, row) in rotation.iter_mut().enumerate() {
            row[k] = one;
        }
        Frame {
            rotation,
            origin: [zero; 3],
            velocity: [zero; 3],
            omega: [zero; 3],
            steps: Vec::new(),
            node: None,
        }
    }

    /// The frame at `translation` (in `parent`'s axes) from `parent`'s
    /// origin, rotated from `parent` by `rotations` in turn (intrinsic); not
    /// yet a node of the kinematic tree (the model stage places it there).
    pub(crate) fn child_frame(
        &mut self,
        parent: &Frame,
        translation: [Id; 3],
        rotations: &[([f64; 3], Id)],
    ) -> Frame {
        let offset = self.rotate(&parent.rotation, translation);
        let origin: [Id; 3] = std::array::from_fn(|k| self.add(parent.origin[k], offset[k]));
        // Origin velocity in parent axes: v_parent + w_parent x t + dt/dt.
        let mut velocity = self.moving_point_velocity(parent, translation);
        let mut rotation = parent.rotation;
        let mut omega = parent.omega;
        let mut steps = parent.steps.clone();
        steps.push(Step::Translate {
            rotation,
            local: translation,
            offset,
        });
        for &(axis, angle) in rotations {
            steps.push(Step::Rotate {
                rotation,
                axis,
                angle,
            });
            let local = self.axis_rotation(axis, angle);
            rotation = self.matmul(&rotation, &local);
            // omega_child = R_local^T omega_parent + axis * angle_dot
            let rate = self.time_derivative_at_zero_acceleration(&[angle])[0];
            velocity = self.rotate_transpose(&local, velocity);
            let rotated = self.rotate_transpose(&local, omega);
            omega = std::array::from_fn(|k| {
                let a = self.constant(axis[k]);
                let term = self.mul(a, rate);
                self.add(rotated[k], term)
            });
        }
        Frame {
            rotation,
            origin,
            velocity,
            omega,
            steps,
            node: None,
        }
    }

    /// The twist `(v, w)` (origin velocity, then angular velocity, in its
    /// own axes) of the frame placed as in [`Self::child_frame`], its
    /// parent at rest: what its own coordinates add to its parent's
    /// motion.
    pub(crate) fn relative_twist(
        &mut self,
        translation: [Id; 3],
        rotations: &[([f64; 3], Id)],
    ) -> [Id; 6] {
        let zero = self.constant(0.0);
        let rate = self.time_derivative_at_zero_acceleration(&translation);
        let mut velocity = [rate[0], rate[1], rate[2]];
        let mut omega = [zero; 3];
        for &(axis, angle) in rotations {
            let local = self.axis_rotation(axis, angle);
            let rate = self.time_derivative_at_zero_acceleration(&[angle])[0];
            velocity = self.rotate_transpose(&local, velocity);
            let rotated = self.rotate_transpose(&local, omega);
            omega = std::array::from_fn(|k| {
                let term = self.scale(rate, axis[k]);
                self.add(rotated[k], term)
            });
        }
        [
            velocity[0],
            velocity[1],
            velocity[2],
            omega[0],
            omega[1],
            omega[2],
        ]
    }

    /// The angular velocity of `frame` and the velocity of the point at
    /// `local` in it (`offset` in world axes), all in world axes, built
    /// along the frame's steps as the recursive algorithms do: a rotation
    /// adds its rate along its axis in world axes (a column combination of
    /// the rotation before it, which it leaves unchanged); a translation
    /// adds the angular velocity across it and its own rate.
    ///
    /// The point's velocity comes twice, equal but written differently:
    /// summed across each translation as above (cheapest to differentiate
    /// in time, for the acceleration bias), and about the point, the cross
    /// product of each rotation's angular velocity with the arm `p - o_i`
    /// from the origin `o_i` it turns about to the point `p`, plus the
    /// translations' own rates. Its derivative by a rate is one cross
    /// product (Pinocchio's form of the Jacobian's column): the UR5's tool
    /// Jacobian in 15 % fewer operations, the Panda's hand in 30 %.
    pub(crate) fn world_velocities(
        &mut self,
        frame: &Frame,
        local: [Id; 3],
        offset: [Id; 3],
    ) -> WorldVelocities {
        let zero = self.constant(0.0);
        let (mut omega, mut own, mut origin) = ([zero; 3], [zero; 3], [zero; 3]);
        let mut linear = [zero; 3];
        // Angular velocity added about each origin, with the origin.
        let mut turns: Vec<([Id; 3], [Id; 3])> = Vec::new();
        let mut pending = [zero; 3];
        let last = Step::Translate {
            rotation: frame.rotation,
            local,
            offset,
        };
        for step in frame.steps.iter().chain([&last]) {
            match *step {
                Step::Translate {
                    rotation,
                    local,
                    offset,
                } => {
                    if pending != [zero; 3] {
                        turns.push((pending, origin));
                        pending = [zero; 3];
                    }
                    origin = std::array::from_fn(|k| self.add(origin[k], offset[k]));
                    let turn = self.cross(omega, offset);
                    let rate = self.time_derivative_at_zero_acceleration(&local);
                    let moved = self.rotate(&rotation, [rate[0], rate[1], rate[2]]);
                    linear = std::array::from_fn(|k| self.sum(&[linear[k], turn[k], moved[k]]));
                    own = std::array::from_fn(|k| self.add(own[k], moved[k]));
                }
                Step::Rotate {
                    rotation,
                    axis,
                    angle,
                } => {
                    let rate = self.time_derivative_at_zero_acceleration(&[angle])[0];
                    let nodes = [0, 1, 2].map(|k| self.constant(axis[k]));
                    let world_axis = self.rotate(&rotation, nodes);
                    for k in 0..3 {
                        let term = self.mul(world_axis[k], rate);
                        omega[k] = self.add(omega[k], term);
                        pending[k] = self.add(pending[k], term);
                    }
                }
            }
        }
        let mut about_point: Vec<Vec<Id>> = own.iter().map(|&x| vec![x]).collect();
        for (w, o) in turns {
            let arm = std::array::from_fn(|k| self.sub(origin[k], o[k]));
            let turn = self.cross(w, arm);
            for (terms, t) in about_point.iter_mut().zip(turn) {
                terms.push(t);
            }
        }
        WorldVelocities {
            angular: omega,
            linear,
            linear_about_point: std::array::from_fn(|k| self.sum(&about_point[k])),
        }
    }

    /// Velocity, in `frame`'s axes, of a point at `local` (which may itself
    /// move): `v_origin + w x local + d(local)/dt`.
    pub(crate) fn moving_point_velocity(&mut self, frame: &Frame, local: [Id; 3]) -> [Id; 3] {
        let rate = self.time_derivative_at_zero_acceleration(&local);
        let w = frame.omega;
        let cross = [
            (w[1], local[2], w[2], local[1]),
            (w[2], local[0], w[0], local[2]),
            (w[0], local[1], w[1], local[0]),
        ];
        std::array::from_fn(|k| {
            let (a, b, c, d) = cross[k];
            let ab = self.mul(a, b);
            let cd = self.mul(c, d);
            self.linear(
                &[
                    (frame.velocity[k], 1.0),
                    (ab, 1.0),
                    (cd, -1.0),
                    (rate[k], 1.0),
                ],
                0.0,
            )
        })
    }
}
