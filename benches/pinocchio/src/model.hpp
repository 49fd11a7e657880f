// Builds a pinocchio::Model joint by joint from plain numbers: those of
// Pinocchio's own URDF parser, written out by dump_model.py. Shared by the
// templated shim (shim.cpp) and the generator of Pinocchio's C
// (generate_c.cpp), so that both time the same model.
#pragma once

#include <pinocchio/multibody.hpp>

#include <exception>
#include <string>

namespace bench_model {

// Adds `joint` if `kind` is its type's Pinocchio short name.
template <class Joint>
bool add_if(pinocchio::Model &model, pinocchio::JointIndex parent, const std::string &kind,
            const Joint &joint, const pinocchio::SE3 &placement, const std::string &name) {
  if (kind != Joint::classname()) return false;
  model.addJoint(parent, joint, placement, name);
  return true;
}

// Pinocchio's one-dof joint of type `kind` (its short name) about or along
// `axis` (used by the unaligned types only); false for any other type.
inline bool add_joint(pinocchio::Model &m, pinocchio::JointIndex parent, const std::string &kind,
                      const Eigen::Vector3d &axis, const pinocchio::SE3 &placement,
                      const std::string &name) {
  using namespace pinocchio;
  return add_if(m, parent, kind, JointModelRX(), placement, name) ||
         add_if(m, parent, kind, JointModelRY(), placement, name) ||
         add_if(m, parent, kind, JointModelRZ(), placement, name) ||
         add_if(m, parent, kind, JointModelRevoluteUnaligned(axis), placement, name) ||
         add_if(m, parent, kind, JointModelPX(), placement, name) ||
         add_if(m, parent, kind, JointModelPY(), placement, name) ||
         add_if(m, parent, kind, JointModelPZ(), placement, name) ||
         add_if(m, parent, kind, JointModelPrismaticUnaligned(axis), placement, name);
}

// A placement from 12 numbers: rotation row by row, then translation.
inline pinocchio::SE3 placement(const double *numbers) {
  const Eigen::Matrix3d rotation =
      Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(numbers);
  return pinocchio::SE3(rotation, Eigen::Map<const Eigen::Vector3d>(numbers + 9));
}

// Appends joint `name` of Pinocchio type `kind` to joint `parent` (0 is the
// universe), placed by `placement` (12 numbers, see above) in the parent
// joint's frame, `axis` (3 numbers) for the unaligned types, carrying the
// rigid inertia `inertia` (mass, centre of mass, rotational inertia about
// it row by row: 13 numbers), with viscous damping `damping`. Returns an
// empty string, or what is wrong (an unknown parent or joint type).
inline std::string append_joint(pinocchio::Model &model, const std::string &name,
                                const std::string &kind, int parent, const double *axis,
                                const double *placement_numbers, const double *inertia,
                                double damping) {
  if (parent < 0 || parent >= model.njoints) {
    return "joint " + name + ": no parent joint " + std::to_string(parent);
  }
  try {
    const auto before = model.njoints;
    if (!add_joint(model, pinocchio::JointIndex(parent), kind,
                   Eigen::Map<const Eigen::Vector3d>(axis), placement(placement_numbers), name)) {
      return "joint " + name + ": type " + kind + " is not a one-dof joint the benchmark builds";
    }
    const pinocchio::JointIndex id = pinocchio::JointIndex(before);
    const Eigen::Matrix3d rotational =
        Eigen::Map<const Eigen::Matrix<double, 3, 3, Eigen::RowMajor>>(inertia + 4);
    model.appendBodyToJoint(
        id, pinocchio::Inertia(inertia[0], Eigen::Map<const Eigen::Vector3d>(inertia + 1), rotational),
        pinocchio::SE3::Identity());
    model.damping[model.joints[id].idx_v()] = damping;
    return "";
  } catch (const std::exception &e) {
    return "joint " + name + ": " + e.what();
  }
}

}  // namespace bench_model
