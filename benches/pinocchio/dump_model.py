"""Loads a URDF with Pinocchio's own parser (Python bindings of the `pin`
wheel), locks the named joints at zero with `buildReducedModel`, and prints
the model's kinematic tree as plain numbers, one joint per line, so that
the benchmark shim can rebuild the same `pinocchio::Model` joint by joint in
its own translation unit (built with the same compiler flags as the
algorithms, `-march=native` included, where the prebuilt parser is not).

Usage: python dump_model.py URDF [LOCKED,JOINTS]

Each line, tab-separated: joint name, Pinocchio's joint type
(`JointModelRZ`, ...), parent joint index, axis (3 numbers; the joint's own
axis for the unaligned types, zeros otherwise), placement in the parent
joint's frame (rotation row by row, 9 numbers, then translation, 3),
the inertia of everything attached to the joint (mass, centre of mass, 3,
rotational inertia about the centre of mass row by row, 9), and the joint
damping. Numbers are written by `repr`, which reads back exactly.
"""

import sys

import pinocchio as pin


def main() -> int:
    if len(sys.argv) not in (2, 3):
        print("usage: dump_model.py URDF [LOCKED,JOINTS]", file=sys.stderr)
        return 2
    urdf = sys.argv[1]
    locked = [n for n in (sys.argv[2] if len(sys.argv) == 3 else "").split(",") if n]
    model = pin.buildModelFromUrdf(urdf)
    for name in locked:
        if not model.existJointName(name):
            print(f"no joint named {name} in {urdf}", file=sys.stderr)
            return 1
    if locked:
        model = pin.buildReducedModel(
            model, [model.getJointId(n) for n in locked], pin.neutral(model)
        )
    for j in range(1, model.njoints):
        joint = model.joints[j]
        kind = joint.shortname()
        if joint.nq != 1 or joint.nv != 1:
            print(
                f"joint {model.names[j]} in {urdf} is a {kind} with {joint.nq} "
                f"configuration and {joint.nv} velocity numbers; the benchmark "
                "takes one-dof joints only",
                file=sys.stderr,
            )
            return 1
        axis = list(joint.extract().axis) if "Unaligned" in kind else [0.0] * 3
        placement = model.jointPlacements[j]
        inertia = model.inertias[j]
        numbers = (
            axis
            + list(placement.rotation.flatten())
            + list(placement.translation)
            + [inertia.mass]
            + list(inertia.lever)
            + list(inertia.inertia.flatten())
            + [model.damping[joint.idx_v]]
        )
        fields = [model.names[j], kind, str(model.parents[j])]
        print("\t".join(fields + [repr(float(x)) for x in numbers]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
