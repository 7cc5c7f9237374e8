#!/usr/bin/env python3
"""Writes the robot descriptions shipped in this folder from published nominal parameters.

Every number below carries its source. The URDFs are generated rather than hand-edited so that
a reviewer checks one table per robot instead of a few hundred lines of XML, and so that the
link frames are derived from the DH table by one documented rule.

    python3 robots/generate.py          # rewrite ur10.urdf, ur10e.urdf, iiwa14.urdf
    python3 robots/generate.py --check  # exit 1 if a committed file differs (run by .ci/run)

UR frames. The URDF link frame of joint i is placed where the joint turns: the transform from link
i-1 to link i is Tx(a[i-1]) Rx(alpha[i-1]) Tz(d[i]) Rz(q[i]). Standard DH frame i is then link frame
i times Tx(a[i]) Rx(alpha[i]), so base_link is DH frame 0 (the controller's base frame) and tool0 is
DH frame 6 (the controller's tool flange: actual_TCP_pose with a zero TCP).
"""

import math
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
PI = math.pi

UR_SOURCE = (
    "Universal Robots, 'DH Parameters for calculations of kinematics and dynamics', "
    "https://www.universal-robots.com/articles/ur/application-installation/"
    "dh-parameters-for-calculations-of-kinematics-and-dynamics/ (CB3 sw 3.7, e-Series sw 5.1)"
)
UR_LIMITS_SOURCE = (
    "UR10 and UR10e technical specifications / user manuals: joint ranges +-360 deg; "
    "max joint speed base and shoulder 120 deg/s, other joints 180 deg/s; "
    "rated joint torques size 4 = 330 Nm, size 3 = 150 Nm, size 2 = 56 Nm"
)

# name, a [m], d [m], alpha [rad], mass [kg], centre of mass in DH frame i [m]
UR10 = {
    "name": "ur10",
    "title": "Universal Robots UR10 (CB3)",
    "dh": [
        (0.0, 0.1273, PI / 2, 7.1, (0.021, 0.000, 0.027)),
        (-0.612, 0.0, 0.0, 12.7, (0.38, 0.000, 0.158)),
        (-0.5723, 0.0, 0.0, 4.27, (0.24, 0.000, 0.068)),
        (0.0, 0.163941, PI / 2, 2.0, (0.000, 0.007, 0.018)),
        (0.0, 0.1157, -PI / 2, 2.0, (0.000, 0.007, 0.018)),
        (0.0, 0.0922, 0.0, 0.365, (0.0, 0.0, -0.026)),
    ],
    "velocity": [2.0944, 2.0944, 3.1416, 3.1416, 3.1416, 3.1416],
    "effort": [330.0, 330.0, 150.0, 56.0, 56.0, 56.0],
}

UR10E = {
    "name": "ur10e",
    "title": "Universal Robots UR10e (e-Series)",
    "dh": [
        (0.0, 0.1807, PI / 2, 7.369, (0.021, 0.000, 0.027)),
        (-0.6127, 0.0, 0.0, 13.051, (0.38, 0.000, 0.158)),
        (-0.57155, 0.0, 0.0, 3.989, (0.24, 0.000, 0.068)),
        (0.0, 0.17415, PI / 2, 2.1, (0.000, 0.007, 0.018)),
        (0.0, 0.11985, -PI / 2, 1.98, (0.000, 0.007, 0.018)),
        (0.0, 0.11655, 0.0, 0.615, (0.0, 0.0, -0.026)),
    ],
    "velocity": [2.0944, 2.0944, 3.1416, 3.1416, 3.1416, 3.1416],
    "effort": [330.0, 330.0, 150.0, 56.0, 56.0, 56.0],
}

UR_LINKS = ["shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link", "wrist_3_link"]
UR_JOINTS = [
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
]
# Housing radius per joint size [m]; coarse shapes made for this project, not measured.
UR_HOUSING_RADIUS = [0.075, 0.075, 0.060, 0.047, 0.047, 0.047]
UR_TUBE_RADIUS = {1: 0.060, 2: 0.045}

IIWA_SOURCE = (
    "KUKA LBR iiwa 14 R820 specification (Pub Spez LBR iiwa): axis-2 height 360 mm, "
    "A2-A4 420 mm, A4-A6 400 mm, A6-flange 126 mm; axis ranges and speeds. The split of "
    "those lengths between link frames and the link masses and centres of mass follow the "
    "community description IFL-CAMP/iiwa_stack (iiwa_description/urdf/iiwa14.xacro), whose "
    "masses are estimates (they sum to 22.5 kg against 29.9 kg in the datasheet)"
)

# joint origin xyz, rpy (frame layout of the community description), range [deg],
# max speed [deg/s] and max torque [Nm] from the KUKA specification,
# link mass [kg] and centre of mass in the link frame [m] (community estimates).
IIWA14_JOINTS = [
    ((0, 0, 0.1575), (0, 0, 0), 170, 85, 320, 4.0, (0, -0.03, 0.12)),
    ((0, 0, 0.2025), (PI / 2, 0, PI), 120, 85, 320, 4.0, (0.0003, 0.059, 0.042)),
    ((0, 0.2045, 0), (PI / 2, 0, PI), 170, 100, 176, 3.0, (0, 0.03, 0.13)),
    ((0, 0, 0.2155), (PI / 2, 0, 0), 120, 75, 176, 2.7, (0, 0.067, 0.034)),
    ((0, 0.1845, 0), (-PI / 2, PI, 0), 170, 130, 110, 1.7, (0.0001, 0.021, 0.076)),
    ((0, 0, 0.2155), (PI / 2, 0, 0), 120, 135, 40, 1.8, (0, 0.0006, 0.0004)),
    ((0, 0.081, 0), (-PI / 2, PI, 0), 175, 135, 40, 0.3, (0, 0, 0.02)),
]
IIWA_FLANGE_Z = 0.045
IIWA_BASE_MASS = (5.0, (-0.1, 0, 0.07))
# Coarse body of each iiwa link: radius [m] and the direction its body runs towards the next joint.
IIWA_BODY = [(0.075, "z", 0.2025), (0.075, "y", 0.2045), (0.07, "z", 0.2155), (0.07, "y", 0.1845),
             (0.065, "z", 0.2155), (0.06, "y", 0.081), (0.05, "z", 0.045)]


def num(value):
    """Shortest text that reads back as the same double (repr), with -0 and tiny noise folded."""
    if abs(value) < 1e-15:
        return "0"
    # Drop binary noise from the frame algebra (-0.23199999999999998 -> -0.232) but keep
    # values such as pi/2 exact: only round when rounding moves the value by float noise.
    rounded = round(float(value), 12)
    return repr(rounded if abs(rounded - value) < 1e-14 else float(value))


def vec(values):
    return " ".join(num(v) for v in values)


def rot_x_apply(alpha, p):
    """Rx(alpha) applied to p, exact for the multiples of pi/2 that DH tables use."""
    c, s = exact_cos(alpha), exact_sin(alpha)
    x, y, z = p
    return (x, c * y - s * z, s * y + c * z)


def exact_sin(angle):
    table = {0.0: 0.0, PI / 2: 1.0, -PI / 2: -1.0, PI: 0.0}
    return table.get(angle, math.sin(angle))


def exact_cos(angle):
    table = {0.0: 1.0, PI / 2: 0.0, -PI / 2: 0.0, PI: -1.0}
    return table.get(angle, math.cos(angle))


def cylinder(radius, length, xyz, rpy=(0, 0, 0)):
    return ("cylinder", f'radius="{num(radius)}" length="{num(length)}"', xyz, rpy)


def along(axis, radius, length, start=0.0):
    """A cylinder from `start` to `start + length` along a link-frame axis."""
    centre = start + length / 2
    if axis == "z":
        return cylinder(radius, abs(length), (0, 0, centre))
    if axis == "y":
        return cylinder(radius, abs(length), (0, centre, 0), (PI / 2, 0, 0))
    return cylinder(radius, abs(length), (centre, 0, 0), (0, PI / 2, 0))


def link_xml(name, inertial=None, shapes=(), comment=None):
    out = []
    if comment:
        out.append(f"  <!-- {comment} -->")
    out.append(f'  <link name="{name}">')
    if inertial:
        mass, com = inertial
        # Inertia tensors are not published; a small isotropic placeholder keeps simulators
        # that require a positive-definite tensor happy. Gravity models use mass and CoM only.
        inertia = max(mass * 0.0025, 1e-4)
        out.append("    <inertial>")
        out.append(f'      <origin xyz="{vec(com)}" rpy="0 0 0"/>')
        out.append(f'      <mass value="{num(mass)}"/>')
        out.append(
            f'      <inertia ixx="{num(inertia)}" ixy="0" ixz="0" iyy="{num(inertia)}" iyz="0" izz="{num(inertia)}"/>'
        )
        out.append("    </inertial>")
    for element in ("visual", "collision"):
        for shape, attrs, xyz, rpy in shapes:
            out.append(f"    <{element}>")
            out.append(f'      <origin xyz="{vec(xyz)}" rpy="{vec(rpy)}"/>')
            out.append(f"      <geometry><{shape} {attrs}/></geometry>")
            if element == "visual":
                out.append('      <material name="cobot_grey"/>')
            out.append(f"    </{element}>")
    out.append("  </link>")
    return out


def joint_xml(name, kind, parent, child, xyz, rpy, limit=None):
    out = [f'  <joint name="{name}" type="{kind}">']
    out.append(f'    <parent link="{parent}"/>')
    out.append(f'    <child link="{child}"/>')
    out.append(f'    <origin xyz="{vec(xyz)}" rpy="{vec(rpy)}"/>')
    if kind != "fixed":
        out.append('    <axis xyz="0 0 1"/>')
    if limit:
        lower, upper, effort, velocity = limit
        out.append(
            f'    <limit lower="{num(lower)}" upper="{num(upper)}" effort="{num(effort)}" velocity="{num(velocity)}"/>'
        )
    out.append("  </joint>")
    return out


def header(robot, title, sources):
    out = ['<?xml version="1.0"?>', "<!--", f"  {title}: generated by robots/generate.py; do not edit by hand."]
    for source in sources:
        out.append(f"  Source: {source}.")
    out.append("  Collision and visual shapes are coarse primitives made for this project.")
    out.append("-->")
    out.append(f'<robot name="{robot}">')
    out.append('  <material name="cobot_grey"><color rgba="0.7 0.7 0.72 1"/></material>')
    return out


def ur_urdf(spec):
    dh = spec["dh"]
    out = header(spec["name"], spec["title"], [UR_SOURCE, UR_LIMITS_SOURCE])
    d1 = dh[0][1]
    out += link_xml("base_link", shapes=[along("z", 0.09, d1 - 0.03)], comment="DH frame 0, the controller's base frame")
    parent = "base_link"
    for i, (a, d, alpha, mass, com_dh) in enumerate(dh):
        prev_a, prev_alpha = (0.0, 0.0) if i == 0 else (dh[i - 1][0], dh[i - 1][2])
        xyz = rot_x_apply(prev_alpha, (0.0, 0.0, d))
        xyz = (prev_a + xyz[0], xyz[1], xyz[2])
        limit = (-2 * PI, 2 * PI, spec["effort"][i], spec["velocity"][i])
        out += joint_xml(UR_JOINTS[i], "revolute", parent, UR_LINKS[i], xyz, (prev_alpha, 0, 0), limit)
        # The published CoM is in standard DH frame i = this link frame * Tx(a) Rx(alpha).
        com = rot_x_apply(alpha, com_dh)
        com = (com[0] + a, com[1], com[2])
        shapes = [cylinder(UR_HOUSING_RADIUS[i], 2.2 * UR_HOUSING_RADIUS[i], (0, 0, 0))]
        if i in UR_TUBE_RADIUS:
            housing = UR_HOUSING_RADIUS[i]
            shapes.append(along("x", UR_TUBE_RADIUS[i], a + 2 * housing, start=-housing))
        if i == 5:
            shapes = [along("z", UR_HOUSING_RADIUS[i], -0.04)]
        out += link_xml(UR_LINKS[i], (mass, com), shapes)
        parent = UR_LINKS[i]
    out += joint_xml("wrist_3_link-tool0_fixed_joint", "fixed", parent, "tool0", (0, 0, 0), (0, 0, 0))
    out += link_xml("tool0", comment="tool flange (DH frame 6)")
    out.append("</robot>")
    return "\n".join(out) + "\n"


def iiwa_urdf():
    out = header("iiwa14", "KUKA LBR iiwa 14 R820", [IIWA_SOURCE])
    base_mass, base_com = IIWA_BASE_MASS
    out += link_xml("iiwa_link_0", (base_mass, base_com), [along("z", 0.11, 0.1575)], comment="robot base")
    parent = "iiwa_link_0"
    for i, (xyz, rpy, range_deg, speed_deg, torque, mass, com) in enumerate(IIWA14_JOINTS):
        child = f"iiwa_link_{i + 1}"
        limit = (-math.radians(range_deg), math.radians(range_deg), torque, math.radians(speed_deg))
        out += joint_xml(f"iiwa_joint_{i + 1}", "revolute", parent, child, xyz, rpy, limit)
        radius, axis, length = IIWA_BODY[i]
        out += link_xml(child, (mass, com), [along(axis, radius, length)])
        parent = child
    out += joint_xml("iiwa_joint_ee", "fixed", parent, "iiwa_link_ee", (0, 0, IIWA_FLANGE_Z), (0, 0, 0))
    out += link_xml("iiwa_link_ee", comment="media flange")
    out.append("</robot>")
    return "\n".join(out) + "\n"


def main():
    outputs = {
        "ur10.urdf": ur_urdf(UR10),
        "ur10e.urdf": ur_urdf(UR10E),
        "iiwa14.urdf": iiwa_urdf(),
    }
    check = "--check" in sys.argv[1:]
    stale = []
    for name, text in outputs.items():
        path = HERE / name
        if check:
            if not path.exists() or path.read_text() != text:
                stale.append(name)
        else:
            path.write_text(text)
            print(f"wrote {path}")
    if stale:
        print(f"out of date with robots/generate.py: {', '.join(stale)}", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
