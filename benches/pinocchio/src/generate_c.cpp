// Pinocchio's algorithms generated to C, the anchor a user of Pinocchio's
// code generation compares with: builds the benchmark's model (the lines
// dump_model.py writes), instantiates rnea, crba, nonLinearEffects, aba and
// computeFrameJacobian over casadi::SX (pinocchio/autodiff/casadi.hpp), and
// writes one C file with CasADi's CodeGenerator, common subexpressions
// eliminated (the `cse` option).
//
// Usage: generate_c MODEL PREFIX OUT.c [derivatives]
//
// Writes OUT.c with the functions PREFIX_rnea (q, v, a -> tau), PREFIX_crba_nle
// (q, v -> M, nle: one program), PREFIX_crba (q -> M), PREFIX_nle (q, v ->
// nle), PREFIX_aba (q, v, tau -> ddq) and, when MODEL has a frame line,
// PREFIX_frame (q -> position, rotation, 6 x nv Jacobian in
// LOCAL_WORLD_ALIGNED) and, with `derivatives`, PREFIX_rnea_derivatives (q,
// v, a -> tau, dtau/dq, dtau/dv) and PREFIX_aba_derivatives (q, v, tau ->
// ddq, dddq/dq, dddq/dv, dddq/dtau): CasADi's Jacobians of the SX rnea and
// aba. CasADi's calling convention, every output dense and
// column-major, M symmetric. As in the templated shim, the joint damping
// `d .* v` is added to tau and nle and subtracted from the torque given to
// aba. Prints, per function: its name, its operation count (CasADi's
// instructions less inputs, outputs and constants) and its work sizes
// (sz_arg, sz_res, sz_iw, sz_w), tab-separated.
#include <pinocchio/autodiff/casadi.hpp>

#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/frames.hpp>
#include <pinocchio/algorithm/jacobian.hpp>
#include <pinocchio/algorithm/kinematics.hpp>
#include <pinocchio/algorithm/rnea.hpp>

#include "model.hpp"

#include <casadi/casadi.hpp>

#include <fstream>
#include <iostream>
#include <sstream>
#include <vector>

namespace {
using SX = casadi::SX;
using ADModel = pinocchio::ModelTpl<SX>;
using ADData = ADModel::Data;
using ADVector = ADModel::VectorXs;

[[noreturn]] void fail(const std::string &message) {
  std::cerr << "generate_c: " << message << "\n";
  std::exit(1);
}

// A column of symbols as an Eigen vector of SX.
ADVector column(const SX &symbols) {
  ADVector out(symbols.size1());
  for (casadi_int i = 0; i < symbols.size1(); ++i) out[i] = symbols(i);
  return out;
}

// A dense SX of an Eigen matrix of SX (structural zeros kept as zeros, so
// that the generated output is dense and column-major).
template <class Derived>
SX dense(const Eigen::MatrixBase<Derived> &m) {
  SX out = SX::zeros(m.rows(), m.cols());
  for (Eigen::Index j = 0; j < m.cols(); ++j) {
    for (Eigen::Index i = 0; i < m.rows(); ++i) out(i, j) = m(i, j);
  }
  return densify(out);
}

// Operations of an SX function: its instructions less inputs, outputs and
// constants.
casadi_int operations(const casadi::Function &f) {
  casadi_int n = 0;
  for (casadi_int k = 0; k < f.n_instructions(); ++k) {
    const auto op = f.instruction_id(k);
    if (op != casadi::OP_INPUT && op != casadi::OP_OUTPUT && op != casadi::OP_CONST) ++n;
  }
  return n;
}

// Reads `count` numbers from `fields` starting at `from`.
std::vector<double> numbers(const std::vector<std::string> &fields, std::size_t from,
                            std::size_t count, const std::string &where) {
  if (fields.size() != from + count) {
    fail(where + ": " + std::to_string(fields.size()) + " fields, expected " +
         std::to_string(from + count));
  }
  std::vector<double> out;
  for (std::size_t k = from; k < fields.size(); ++k) {
    try {
      out.push_back(std::stod(fields[k]));
    } catch (const std::exception &) {
      fail(where + ": " + fields[k] + " is not a number");
    }
  }
  return out;
}
}  // namespace

int main(int argc, char **argv) {
  if (argc != 4 && !(argc == 5 && std::string(argv[4]) == "derivatives")) {
    fail("usage: generate_c MODEL PREFIX OUT.c [derivatives]");
  }
  const std::string path = argv[1], prefix = argv[2], out = argv[3];
  const bool derivatives = argc == 5;
  std::ifstream in(path);
  if (!in) fail("cannot read " + path);
  pinocchio::Model model;
  bool has_frame = false;
  pinocchio::FrameIndex frame = 0;
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    std::vector<std::string> fields;
    std::stringstream split(line);
    for (std::string field; std::getline(split, field, '\t');) fields.push_back(field);
    const std::string where = path + ", line " + std::to_string(number);
    if (fields.empty()) fail(where + ": empty line");
    if (fields[0] == "joint") {
      if (fields.size() < 4) fail(where + ": too few fields");
      const auto x = numbers(fields, 4, 29, where);
      const std::string error = bench_model::append_joint(
          model, fields[1], fields[2], std::stoi(fields[3]), &x[0], &x[3], &x[15], x[28]);
      if (!error.empty()) fail(where + ": " + error);
    } else if (fields[0] == "frame") {
      if (fields.size() < 3) fail(where + ": too few fields");
      const auto x = numbers(fields, 3, 12, where);
      const auto parent = pinocchio::JointIndex(std::stoi(fields[2]));
      if (parent >= pinocchio::JointIndex(model.njoints)) fail(where + ": no such joint");
      frame = model.addFrame(pinocchio::Frame(fields[1], parent, pinocchio::FrameIndex(0),
                                              bench_model::placement(x.data()),
                                              pinocchio::OP_FRAME));
      has_frame = true;
    } else if (fields[0] != "locked") {
      fail(where + ": unknown record " + fields[0]);
    }
  }

  const ADModel ad = model.cast<SX>();
  ADData data(ad);
  const int n = model.nv;
  const SX q = SX::sym("q", n), v = SX::sym("v", n), a = SX::sym("a", n), tau = SX::sym("tau", n);
  const ADVector qe = column(q), ve = column(v), ae = column(a), taue = column(tau);
  const ADVector damping = model.damping.cast<SX>();
  const ADVector damping_force = damping.cwiseProduct(ve);

  const auto mass_matrix = [&]() {
    pinocchio::crba(ad, data, qe);
    ADModel::MatrixXs m = data.M;
    m.triangularView<Eigen::StrictlyLower>() = m.transpose().triangularView<Eigen::StrictlyLower>();
    return dense(m);
  };
  const auto nle = [&]() {
    const ADVector h = pinocchio::nonLinearEffects(ad, data, qe, ve) + damping_force;
    return dense(h);
  };

  std::vector<casadi::Function> functions;
  const casadi::Dict cse{{"cse", true}};
  {
    const ADVector t = pinocchio::rnea(ad, data, qe, ve, ae) + damping_force;
    functions.emplace_back(prefix + "_rnea", std::vector<SX>{q, v, a}, std::vector<SX>{dense(t)}, cse);
  }
  {
    const SX m = mass_matrix();
    const SX h = nle();
    functions.emplace_back(prefix + "_crba_nle", std::vector<SX>{q, v}, std::vector<SX>{m, h}, cse);
  }
  functions.emplace_back(prefix + "_crba", std::vector<SX>{q}, std::vector<SX>{mass_matrix()}, cse);
  functions.emplace_back(prefix + "_nle", std::vector<SX>{q, v}, std::vector<SX>{nle()}, cse);
  {
    const ADVector torque = taue - damping_force;
    const ADVector ddq = pinocchio::aba(ad, data, qe, ve, torque);
    functions.emplace_back(prefix + "_aba", std::vector<SX>{q, v, tau}, std::vector<SX>{dense(ddq)}, cse);
  }
  if (derivatives) {
    // CasADi's Jacobians of the generated rnea and aba (what a user of
    // Pinocchio's code generation gets without the analytical derivatives).
    const ADVector t = pinocchio::rnea(ad, data, qe, ve, ae) + damping_force;
    const SX ts = dense(t);
    functions.emplace_back(prefix + "_rnea_derivatives", std::vector<SX>{q, v, a},
                           std::vector<SX>{ts, densify(jacobian(ts, q)), densify(jacobian(ts, v))},
                           cse);
    const ADVector torque = taue - damping_force;
    const ADVector ddq = pinocchio::aba(ad, data, qe, ve, torque);
    const SX d = dense(ddq);
    functions.emplace_back(prefix + "_aba_derivatives", std::vector<SX>{q, v, tau},
                           std::vector<SX>{d, densify(jacobian(d, q)), densify(jacobian(d, v)),
                                           densify(jacobian(d, tau))},
                           cse);
  }
  if (has_frame) {
    ADData::Matrix6x jacobian = ADData::Matrix6x::Zero(6, n);
    pinocchio::computeFrameJacobian(ad, data, qe, frame, pinocchio::LOCAL_WORLD_ALIGNED, jacobian);
    const auto &pose = data.oMf[frame];
    functions.emplace_back(prefix + "_frame", std::vector<SX>{q},
                           std::vector<SX>{dense(pose.translation()), dense(pose.rotation()),
                                           dense(jacobian)},
                           cse);
  }

  const auto slash = out.find_last_of('/');
  const std::string dir = slash == std::string::npos ? "" : out.substr(0, slash + 1);
  const std::string file = slash == std::string::npos ? out : out.substr(slash + 1);
  casadi::CodeGenerator gen(file, casadi::Dict{{"with_header", false}});
  for (const auto &f : functions) {
    gen.add(f);
    std::cout << f.name() << '\t' << operations(f) << '\t' << f.sz_arg() << '\t' << f.sz_res()
              << '\t' << f.sz_iw() << '\t' << f.sz_w() << '\n';
  }
  gen.generate(dir);
  return 0;
}
