// A thin C interface to Pinocchio for the side-by-side benchmark: builds a
// pinocchio::Model joint by joint from plain numbers (those of Pinocchio's
// own URDF parser, written out by dump_model.py at build time), and runs
// crba + nonLinearEffects, rnea and aba (and their analytical derivatives,
// computeRNEADerivatives and computeABADerivatives) on caller-owned arrays, and a
// frame's placement and Jacobian (computeFrameJacobian). The model is
// built here, not by the prebuilt parser: that library is compiled for
// SSE2 with Eigen's 16-byte alignment, and handing it a Model compiled with
// -march=native (32- or 64-byte alignment) crashes; everything this file
// touches is compiled from Pinocchio's headers with this file's flags.
// Pinocchio keeps the joint damping in `model.damping` but its algorithms
// leave it out; flexdyn's imported scenes have it as dampers, so the
// damping force `damping .* v` is added here (to the bias and inverse
// dynamics, subtracted from the torque for aba). The timed entry points only
// compute (results stay in Pinocchio's Data); separate readers copy them out
// for the comparison.
#include <pinocchio/algorithm/aba-derivatives.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea-derivatives.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>

#include "model.hpp"

#include <cstring>
#include <string>

namespace {
struct Bench {
  pinocchio::Model model;
  pinocchio::Data data;
  Eigen::VectorXd tau_damped;
  pinocchio::Data::Matrix6x jacobian;
};

void write_error(char *err, std::size_t len, const std::string &msg) {
  if (err == nullptr || len == 0) return;
  std::strncpy(err, msg.c_str(), len - 1);
  err[len - 1] = '\0';
}

using VecMap = Eigen::Map<const Eigen::VectorXd>;

}  // namespace

extern "C" {

// An empty model, to be filled by pin_bench_add_joint and closed by
// pin_bench_finish.
void *pin_bench_new() { return new Bench(); }

// Appends joint `name` of Pinocchio type `kind` to joint `parent` (0 is the
// universe), placed by `placement` (rotation row by row, then translation:
// 12 numbers) in the parent joint's frame, `axis` (3 numbers) for the
// unaligned types, carrying the rigid inertia `inertia` (mass, centre of
// mass, rotational inertia about it row by row: 13 numbers), with viscous
// damping `damping`. Returns 0, or -1 with a message in `err` when the
// parent does not exist or the type is not a one-dof joint this shim knows.
int pin_bench_add_joint(void *p, const char *name, const char *kind, int parent,
                        const double *axis, const double *placement, const double *inertia,
                        double damping, char *err, std::size_t errlen) {
  const std::string error = bench_model::append_joint(static_cast<Bench *>(p)->model, name, kind,
                                                      parent, axis, placement, inertia, damping);
  if (error.empty()) return 0;
  write_error(err, errlen, error);
  return -1;
}

// Allocates the algorithms' workspace for the finished model.
void pin_bench_finish(void *p) {
  auto *b = static_cast<Bench *>(p);
  b->data = pinocchio::Data(b->model);
  b->tau_damped = Eigen::VectorXd::Zero(b->model.nv);
  b->jacobian = pinocchio::Data::Matrix6x::Zero(6, b->model.nv);
}

// Placement in the world of joint `joint` at `q` (rotation row by row, then
// translation: 12 numbers), by forwardKinematics.
void pin_bench_joint_placement(void *p, const double *q, int joint, double *out) {
  auto *b = static_cast<Bench *>(p);
  pinocchio::forwardKinematics(b->model, b->data, VecMap(q, b->model.nv));
  const auto &m = b->data.oMi[pinocchio::JointIndex(joint)];
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) out[3 * i + j] = m.rotation()(i, j);
    out[9 + i] = m.translation()[i];
  }
}

// Adds a frame fixed to joint `joint` at `placement` (12 numbers, as above)
// in the joint's frame and rebuilds the workspace; returns its index.
int pin_bench_add_frame(void *p, int joint, const double *placement) {
  auto *b = static_cast<Bench *>(p);
  const pinocchio::SE3 frame = bench_model::placement(placement);
  const auto parent = pinocchio::JointIndex(joint);
  const auto id = b->model.addFrame(
      pinocchio::Frame("bench_frame", parent, pinocchio::FrameIndex(0), frame, pinocchio::OP_FRAME));
  b->data = pinocchio::Data(b->model);
  return int(id);
}

// The frame's placement and its Jacobian in LOCAL_WORLD_ALIGNED:
// computeFrameJacobian (forward kinematics to the frame's joint included).
void pin_bench_frame_jacobian(void *p, int frame, const double *q) {
  auto *b = static_cast<Bench *>(p);
  b->jacobian.setZero();
  pinocchio::computeFrameJacobian(b->model, b->data, VecMap(q, b->model.nv),
                                  pinocchio::FrameIndex(frame), pinocchio::LOCAL_WORLD_ALIGNED,
                                  b->jacobian);
}

// Copies the last frame Jacobian's results out: position (3), rotation (row
// by row, 9), Jacobian (6 x nv, column-major).
void pin_bench_read_frame(const void *p, int frame, double *position, double *rotation,
                          double *jacobian) {
  const auto *b = static_cast<const Bench *>(p);
  const auto &m = b->data.oMf[pinocchio::FrameIndex(frame)];
  for (int i = 0; i < 3; ++i) {
    position[i] = m.translation()[i];
    for (int j = 0; j < 3; ++j) rotation[3 * i + j] = m.rotation()(i, j);
  }
  for (int k = 0; k < 6 * b->model.nv; ++k) jacobian[k] = b->jacobian.data()[k];
}

void pin_bench_free(void *b) { delete static_cast<Bench *>(b); }

int pin_bench_nv(const void *b) { return static_cast<const Bench *>(b)->model.nv; }

// Name of the joint whose velocity has index `i` (one-dof joints only).
const char *pin_bench_joint_name(const void *b, int i) {
  const auto &m = static_cast<const Bench *>(b)->model;
  for (pinocchio::JointIndex j = 1; j < m.joints.size(); ++j) {
    if (m.joints[j].idx_v() == i) return m.names[j].c_str();
  }
  return "";
}

void pin_bench_crba_nle(void *p, const double *q, const double *v) {
  auto *b = static_cast<Bench *>(p);
  const int n = b->model.nv;
  pinocchio::crba(b->model, b->data, VecMap(q, n));
  pinocchio::nonLinearEffects(b->model, b->data, VecMap(q, n), VecMap(v, n));
}

void pin_bench_rnea(void *p, const double *q, const double *v, const double *a) {
  auto *b = static_cast<Bench *>(p);
  const int n = b->model.nv;
  pinocchio::rnea(b->model, b->data, VecMap(q, n), VecMap(v, n), VecMap(a, n));
}

void pin_bench_aba(void *p, const double *q, const double *v, const double *tau) {
  auto *b = static_cast<Bench *>(p);
  const int n = b->model.nv;
  b->tau_damped = VecMap(tau, n) - b->model.damping.cwiseProduct(VecMap(v, n));
  pinocchio::aba(b->model, b->data, VecMap(q, n), VecMap(v, n), b->tau_damped);
}

void pin_bench_rnea_derivatives(void *p, const double *q, const double *v, const double *a) {
  auto *b = static_cast<Bench *>(p);
  const int n = b->model.nv;
  pinocchio::computeRNEADerivatives(b->model, b->data, VecMap(q, n), VecMap(v, n), VecMap(a, n));
}

void pin_bench_aba_derivatives(void *p, const double *q, const double *v, const double *tau) {
  auto *b = static_cast<Bench *>(p);
  const int n = b->model.nv;
  b->tau_damped = VecMap(tau, n) - b->model.damping.cwiseProduct(VecMap(v, n));
  pinocchio::computeABADerivatives(b->model, b->data, VecMap(q, n), VecMap(v, n), b->tau_damped);
}

// Copies the last computeRNEADerivatives out (column-major): dtau/dq, and
// dtau/dv with the damping's diag(d) added.
void pin_bench_read_rnea_derivatives(const void *p, double *dq, double *dv) {
  const auto *b = static_cast<const Bench *>(p);
  const int n = b->model.nv;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      dq[i + n * j] = b->data.dtau_dq(i, j);
      dv[i + n * j] = b->data.dtau_dv(i, j) + (i == j ? b->model.damping[j] : 0.0);
    }
  }
}

// Copies the last computeABADerivatives out (column-major): ddq/dq, ddq/dv
// less M^-1 diag(d) (the damping's part), and M^-1 (symmetrised) = ddq/dtau.
void pin_bench_read_aba_derivatives(const void *p, double *dq, double *dv, double *minv) {
  const auto *b = static_cast<const Bench *>(p);
  const int n = b->model.nv;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      const double m = i <= j ? b->data.Minv(i, j) : b->data.Minv(j, i);
      minv[i + n * j] = m;
      dq[i + n * j] = b->data.ddq_dq(i, j);
      dv[i + n * j] = b->data.ddq_dv(i, j) - m * b->model.damping[j];
    }
  }
}

// Copies the last results out: M (symmetrised, column-major), nle and tau
// (each with the damping force at velocity `v` added), ddq.
void pin_bench_read(const void *p, const double *v, double *m, double *nle, double *tau,
                    double *ddq) {
  const auto *b = static_cast<const Bench *>(p);
  const int n = b->model.nv;
  for (int j = 0; j < n; ++j) {
    for (int i = 0; i < n; ++i) {
      m[i + n * j] = i <= j ? b->data.M(i, j) : b->data.M(j, i);
    }
    const double damping = b->model.damping[j] * v[j];
    nle[j] = b->data.nle[j] + damping;
    tau[j] = b->data.tau[j] + damping;
    ddq[j] = b->data.ddq[j];
  }
}
}
