// A thin C interface to Pinocchio for the side-by-side benchmark: loads a
// URDF (optionally locking some joints at zero, as Pinocchio's
// buildReducedModel does), and runs crba + nonLinearEffects, rnea and aba
// on caller-owned arrays. Pinocchio keeps the URDF's joint damping in
// `model.damping` but its algorithms leave it out; flexdyn's imported scenes
// have it as dampers, so the damping force `damping .* v` is added here
// (to the bias and inverse dynamics, subtracted from the torque for aba). The timed entry points only compute (results stay
// in Pinocchio's Data); separate readers copy them out for the comparison.
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/model.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/multibody.hpp>
#include <pinocchio/parsers/urdf.hpp>

#include <cstring>
#include <exception>
#include <sstream>
#include <string>
#include <vector>

namespace {
struct Bench {
  pinocchio::Model model;
  pinocchio::Data data;
  Eigen::VectorXd tau_damped;
  explicit Bench(const pinocchio::Model &m) : model(m), data(m), tau_damped(m.nv) {}
};

void write_error(char *err, std::size_t len, const std::string &msg) {
  if (err == nullptr || len == 0) return;
  std::strncpy(err, msg.c_str(), len - 1);
  err[len - 1] = '\0';
}

using VecMap = Eigen::Map<const Eigen::VectorXd>;
}  // namespace

extern "C" {

// Loads `urdf`; `locked` is a comma-separated list of joint names fixed at
// zero (empty for none). Returns null and writes a message into `err` on
// failure, or when a joint's configuration is not one number per velocity.
void *pin_bench_new(const char *urdf, const char *locked, char *err, std::size_t errlen) {
  try {
    pinocchio::Model full;
    pinocchio::urdf::buildModel(std::string(urdf), full);
    std::vector<pinocchio::JointIndex> lock;
    std::stringstream names{std::string(locked)};
    std::string name;
    while (std::getline(names, name, ',')) {
      if (name.empty()) continue;
      if (!full.existJointName(name)) {
        write_error(err, errlen, "no joint named " + name + " in " + urdf);
        return nullptr;
      }
      lock.push_back(full.getJointId(name));
    }
    pinocchio::Model model =
        lock.empty() ? full
                     : pinocchio::buildReducedModel(full, lock, pinocchio::neutral(full));
    if (model.nq != model.nv) {
      write_error(err, errlen, "configuration size differs from velocity size (continuous joints?)");
      return nullptr;
    }
    return new Bench(model);
  } catch (const std::exception &e) {
    write_error(err, errlen, e.what());
    return nullptr;
  }
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
