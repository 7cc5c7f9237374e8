#!/usr/bin/env python3
"""Independent reader of `ips align|diagnose --export FORMAT` output (DESIGN.md 6.4).

Reads the export on stdin, parses it the way the receiving software would (XML for URDF and SDF,
the command line for ros-tf, the KRL FRAME and URScript literals, RFC 4180 CSV), turns it into a
pose with its own maths (standard library only) and compares it with the same command's `--json`
report. Exit code 0 when they agree, 1 with the difference otherwise.

    ips align S --json > report.json
    ips align S --export kuka-base | scripts/check-export.py kuka-base report.json
"""
import csv
import io
import json
import math
import re
import shlex
import sys
import xml.etree.ElementTree as ET

NUMBER = r"(-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?)"
POSITION_TOLERANCE_M = 1e-6
ROTATION_TOLERANCE_RAD = 1e-5


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def rot_x(t):
    c, s = math.cos(t), math.sin(t)
    return [[1, 0, 0], [0, c, -s], [0, s, c]]


def rot_y(t):
    c, s = math.cos(t), math.sin(t)
    return [[c, 0, s], [0, 1, 0], [-s, 0, c]]


def rot_z(t):
    c, s = math.cos(t), math.sin(t)
    return [[c, -s, 0], [s, c, 0], [0, 0, 1]]


def from_rpy(roll, pitch, yaw):
    """URDF, SDF: fixed axes X, then Y, then Z."""
    return matmul(rot_z(yaw), matmul(rot_y(pitch), rot_x(roll)))


def from_quaternion(x, y, z, w):
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / norm, y / norm, z / norm, w / norm
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ]


def from_rotation_vector(rx, ry, rz):
    """Rodrigues' formula."""
    angle = math.sqrt(rx * rx + ry * ry + rz * rz)
    if angle < 1e-15:
        return [[1, 0, 0], [0, 1, 0], [0, 0, 1]]
    kx, ky, kz = rx / angle, ry / angle, rz / angle
    k = [[0, -kz, ky], [kz, 0, -kx], [-ky, kx, 0]]
    k2 = matmul(k, k)
    s, c = math.sin(angle), 1 - math.cos(angle)
    return [[(1 if i == j else 0) + s * k[i][j] + c * k2[i][j] for j in range(3)] for i in range(3)]


def rotation_difference_rad(a, b):
    """Angle of a^T b."""
    trace = sum(a[k][i] * b[k][i] for i in range(3) for k in range(3))
    return math.acos(max(-1.0, min(1.0, (trace - 1) / 2)))


def fail(message):
    print(f"check-export: {message}", file=sys.stderr)
    sys.exit(1)


def numbers(text, count, what):
    values = [float(v) for v in text.split()]
    if len(values) != count:
        fail(f"{what} has {len(values)} numbers, expected {count}: '{text}'")
    return values


def parse_urdf(text):
    robot = ET.fromstring(text)
    if robot.tag != "robot" or robot.get("name") != "aligned_part":
        fail("the URDF's root is not <robot name=\"aligned_part\">")
    links = [link.get("name") for link in robot.findall("link")]
    joint = robot.find("joint[@name='part_joint']")
    if joint is None or joint.get("type") != "fixed":
        fail("no fixed joint named part_joint")
    parent, child = joint.find("parent").get("link"), joint.find("child").get("link")
    if child != "part" or parent not in links or "part" not in links:
        fail(f"part_joint joins {parent} to {child}; links {links}")
    origin = joint.find("origin")
    return numbers(origin.get("xyz"), 3, "origin xyz"), from_rpy(*numbers(origin.get("rpy"), 3, "origin rpy")), parent


def parse_sdf(text):
    sdf = ET.fromstring(text)
    if sdf.tag != "sdf" or sdf.get("version") != "1.9":
        fail("the root is not <sdf version=\"1.9\">")
    model = sdf.find("model[@name='part']")
    if model is None or model.findtext("static") != "true":
        fail("no static model named part")
    values = numbers(model.findtext("pose"), 6, "model pose")
    return values[:3], from_rpy(*values[3:]), None


def parse_ros_tf(text):
    words = shlex.split(text)
    if words[:4] != ["ros2", "run", "tf2_ros", "static_transform_publisher"]:
        fail(f"not a static_transform_publisher command: {words[:4]}")
    flags = dict(zip(words[4::2], words[5::2]))
    if flags.get("--child-frame-id") != "part":
        fail("the child frame is not 'part'")
    value = lambda name: float(flags[f"--{name}"])
    xyz = [value("x"), value("y"), value("z")]
    return xyz, from_quaternion(value("qx"), value("qy"), value("qz"), value("qw")), flags.get("--frame-id")


def parse_kuka_base(text):
    match = re.fullmatch(r"\{X N,Y N,Z N,A N,B N,C N\}".replace("N", NUMBER), text.strip())
    if not match:
        fail(f"not a KRL FRAME literal: '{text.strip()}'")
    x, y, z, a, b, c = (float(v) for v in match.groups())
    rotation = matmul(rot_z(math.radians(a)), matmul(rot_y(math.radians(b)), rot_x(math.radians(c))))
    return [x / 1e3, y / 1e3, z / 1e3], rotation, None


def parse_ur_pose(text):
    match = re.fullmatch(r"p\[N, N, N, N, N, N\]".replace("N", NUMBER), text.strip())
    if not match:
        fail(f"not a URScript pose literal: '{text.strip()}'")
    x, y, z, rx, ry, rz = (float(v) for v in match.groups())
    return [x, y, z], from_rotation_vector(rx, ry, rz), None


def check_csv(text, report):
    rows = list(csv.reader(io.StringIO(text)))
    if rows[0] != ["id", "x_m", "y_m", "z_m", "residual_m"]:
        fail(f"CSV header is {rows[0]}")
    if "inspections" in report:
        expected = [(i["id"], i["ball_centre_after"], i["residual_after"]) for i in report["inspections"]]
    else:
        expected = [(r["id"], r["ball_centre"], r["distance"]) for r in report["residuals"]]
    if len(rows) - 1 != len(expected):
        fail(f"CSV has {len(rows) - 1} rows, the report {len(expected)} touches")
    for row, (touch, centre, residual) in zip(rows[1:], expected):
        values = [float(v) for v in row[1:]]
        if row[0] != touch or max(abs(a - b) for a, b in zip(values, centre + [residual])) > POSITION_TOLERANCE_M:
            fail(f"CSV row {row} differs from the report's {touch} {centre} {residual}")
    print(f"check-export: csv agrees with the report ({len(expected)} touches)")


def main():
    if len(sys.argv) != 3:
        fail("usage: check-export.py FORMAT REPORT.json < export")
    fmt, report = sys.argv[1], json.load(open(sys.argv[2]))
    text = sys.stdin.read()
    if fmt == "csv":
        return check_csv(text, report)
    parsers = {"urdf": parse_urdf, "sdf": parse_sdf, "ros-tf": parse_ros_tf,
               "kuka-base": parse_kuka_base, "ur-pose": parse_ur_pose}
    if fmt not in parsers:
        fail(f"unknown format {fmt}")
    xyz, rotation, base = parsers[fmt](text)
    pose = report.get("pose_after") or report["pose"]
    position_error = math.dist(xyz, pose["xyz"])
    rotation_error = rotation_difference_rad(rotation, from_rpy(*pose["rpy"]))
    if position_error > POSITION_TOLERANCE_M or rotation_error > ROTATION_TOLERANCE_RAD:
        fail(f"{fmt}: pose differs from the report by {position_error:.3g} m and {rotation_error:.3g} rad")
    if base is not None and report.get("base_frame") and base != report["base_frame"]:
        fail(f"{fmt}: base frame '{base}', the report's '{report['base_frame']}'")
    print(f"check-export: {fmt} agrees with the report ({position_error:.2g} m, {rotation_error:.2g} rad)")


if __name__ == "__main__":
    main()
