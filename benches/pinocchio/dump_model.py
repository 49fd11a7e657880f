"""Loads a URDF with Pinocchio's own parser (Python bindings of the `pin`
wheel), locks joints at their neutral position with `buildReducedModel`,
and prints the model's kinematic tree as plain numbers, so that the
benchmark can rebuild the same `pinocchio::Model` joint by joint in its own
translation units: the templated shim (built with the same compiler flags
as the algorithms, `-march=native` included, where the prebuilt parser is
not) and the generator of Pinocchio's C (`src/generate_c.cpp`).

Usage: python dump_model.py URDF LOCKED [LINK]

LOCKED is a comma-separated list of the joints to lock, or `only:` and the
joints to keep moving (every other joint is locked); LINK, when given, is a
link whose frame is printed too.

One record per line, tab-separated, its type first:

* `locked`, the comma-separated names of the locked joints (the first line);
* `joint`, per joint: name, Pinocchio's joint type (`JointModelRZ`, ...),
  parent joint index (a continuous joint written as the revolute joint of
  its angle), axis (3 numbers; the joint's own axis for the
  unaligned types, zeros otherwise), placement in the parent joint's frame
  (rotation row by row, 9 numbers, then translation, 3), the inertia of
  everything attached to the joint (mass, centre of mass, 3, rotational
  inertia about the centre of mass row by row, 9), and the joint damping;
* `frame`, for LINK: its name, the index of the joint it is fixed to and
  its placement in that joint's frame (12 numbers, as above).

Numbers are written by `repr`, which reads back exactly.
"""

import sys

import pinocchio as pin


# Pinocchio's unbounded revolute joints and the revolute joints written for
# them.
UNBOUNDED = {
    "JointModelRUBX": "JointModelRX",
    "JointModelRUBY": "JointModelRY",
    "JointModelRUBZ": "JointModelRZ",
    "JointModelRevoluteUnboundedUnaligned": "JointModelRevoluteUnaligned",
}


def flat(placement):
    return list(placement.rotation.flatten()) + list(placement.translation)


def main() -> int:
    if len(sys.argv) not in (3, 4):
        print("usage: dump_model.py URDF LOCKED [LINK]", file=sys.stderr)
        return 2
    urdf, spec = sys.argv[1], sys.argv[2]
    link = sys.argv[3] if len(sys.argv) == 4 else None
    model = pin.buildModelFromUrdf(urdf)
    names = [model.names[j] for j in range(1, model.njoints)]
    if spec.startswith("only:"):
        keep = [n for n in spec[len("only:"):].split(",") if n]
        locked = [n for n in names if n not in keep]
        listed = keep
    else:
        locked = [n for n in spec.split(",") if n]
        listed = locked
    for name in listed:
        if name not in names:
            print(f"no joint named {name} in {urdf}", file=sys.stderr)
            return 1
    if locked:
        model = pin.buildReducedModel(
            model, [model.getJointId(n) for n in locked], pin.neutral(model)
        )
    print("\t".join(["locked", ",".join(locked)]))
    for j in range(1, model.njoints):
        joint = model.joints[j]
        kind = joint.shortname()
        # A continuous joint (unbounded revolute, configuration cos and sin)
        # has the dynamics of a revolute joint about the same axis in its
        # angle, which is what flexdyn's coordinate is.
        unbounded = kind in UNBOUNDED
        kind = UNBOUNDED.get(kind, kind)
        if joint.nq != (2 if unbounded else 1) or joint.nv != 1:
            print(
                f"joint {model.names[j]} in {urdf} is a {kind} with {joint.nq} "
                f"configuration and {joint.nv} velocity numbers; the benchmark "
                "takes one-dof joints only",
                file=sys.stderr,
            )
            return 1
        axis = list(joint.extract().axis) if "Unaligned" in kind else [0.0] * 3
        inertia = model.inertias[j]
        numbers = (
            axis
            + flat(model.jointPlacements[j])
            + [inertia.mass]
            + list(inertia.lever)
            + list(inertia.inertia.flatten())
            + [model.damping[joint.idx_v]]
        )
        fields = ["joint", model.names[j], kind, str(model.parents[j])]
        print("\t".join(fields + [repr(float(x)) for x in numbers]))
    if link is not None:
        if not model.existFrame(link):
            print(f"no link named {link} in {urdf}", file=sys.stderr)
            return 1
        frame = model.frames[model.getFrameId(link)]
        fields = ["frame", link, str(frame.parentJoint)]
        print("\t".join(fields + [repr(float(x)) for x in flat(frame.placement)]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
