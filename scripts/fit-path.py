#!/usr/bin/env python3
"""How well a pose fits a CAD scan scene, and what lies between it and the truth.

For a scene written by `cad-scans --out DIR` (trial-NNNN/ with cloud.ply, part.stl, truth.json),
walks the straight path (on SE(3), in the part's frame) from a pose to the scene's truth and
prints, at each of 11 steps, the cloud points within 0.5 and 1 mm of the part and a Tukey cost
(1.5 and 3 mm scales). A count that dips between the two ends is a ridge no local step crosses;
a flat count means the scan cannot tell the two poses apart. Also prints, at both ends, the
points more than a robust standard deviation off the part behind its surface (by the triangle's
normal) and in front. docs/cad-scan-trials.md (thirty-fifth session) quotes its output.

Needs Open3D (scripts/peer-env.sh installs it in .venv):

    .venv/bin/python scripts/fit-path.py SCENES/trial-0001 --pose 0.5969,0.0449,0.1611,-0.003,0.002,-0.635

The pose is x,y,z (m) and roll,pitch,yaw (rad), as `ips align-cloud --pose` takes it.
"""

import argparse
import json
import math
import sys

import numpy as np

try:
    import open3d as o3d
except ImportError:
    sys.exit("fit-path.py needs Open3D: run scripts/peer-env.sh and use .venv/bin/python")


def pose_from_xyz_rpy(values):
    x, y, z, roll, pitch, yaw = values
    cr, sr = math.cos(roll), math.sin(roll)
    cp, sp = math.cos(pitch), math.sin(pitch)
    cy, sy = math.cos(yaw), math.sin(yaw)
    base_from_part = np.eye(4)
    base_from_part[:3, :3] = [
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ]
    base_from_part[:3, 3] = [x, y, z]
    return base_from_part


def skew(vector):
    return np.array(
        [[0, -vector[2], vector[1]], [vector[2], 0, -vector[0]], [-vector[1], vector[0], 0]]
    )


def rotation_log(rotation):
    angle = math.acos(max(-1.0, min(1.0, (np.trace(rotation) - 1) / 2)))
    if angle < 1e-12:
        return np.zeros(3)
    axis = np.array(
        [
            rotation[2, 1] - rotation[1, 2],
            rotation[0, 2] - rotation[2, 0],
            rotation[1, 0] - rotation[0, 1],
        ]
    ) / (2 * math.sin(angle))
    return axis * angle


def rotation_exp(rotation_vector):
    angle = np.linalg.norm(rotation_vector)
    if angle < 1e-12:
        return np.eye(3)
    k = skew(rotation_vector / angle)
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * k @ k


class Scene:
    def __init__(self, directory):
        mesh = o3d.io.read_triangle_mesh(f"{directory}/part.stl")
        if len(mesh.triangles) == 0:
            sys.exit(f"{directory}/part.stl: no triangles")
        mesh.compute_triangle_normals()
        self.normals = np.asarray(mesh.triangle_normals)
        self.cloud = np.asarray(o3d.io.read_point_cloud(f"{directory}/cloud.ply").points)
        with open(f"{directory}/truth.json") as file:
            self.truth = np.array(json.load(file))
        self.raycasting = o3d.t.geometry.RaycastingScene()
        self.raycasting.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))

    def residuals(self, base_from_part):
        """Each cloud point's distance to the part and its signed offset along the normal."""
        part_from_base = np.linalg.inv(base_from_part)
        in_part = self.cloud @ part_from_base[:3, :3].T + part_from_base[:3, 3]
        closest = self.raycasting.compute_closest_points(
            o3d.core.Tensor(in_part.astype(np.float32))
        )
        surface = closest["points"].numpy()
        normals = self.normals[closest["primitive_ids"].numpy()]
        offset = in_part - surface
        return np.linalg.norm(offset, axis=1), np.einsum("ij,ij->i", offset, normals)


def tukey_cost(distances, scale):
    ratio = np.minimum(distances / scale, 1.0)
    return float(np.sum(scale * scale / 6 * (1 - (1 - ratio * ratio) ** 3)))


def sides(distances, signed, near_m=0.004):
    near = distances < near_m
    sigma = 1.4826 * np.median(distances[near])
    return int((signed[near] < -sigma).sum()), int((signed[near] > sigma).sum())


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", help="a trial directory written by cad-scans --out")
    parser.add_argument("--pose", required=True, help="x,y,z,roll,pitch,yaw (m, rad)")
    parser.add_argument("--steps", type=int, default=10)
    args = parser.parse_args()
    try:
        values = [float(v) for v in args.pose.split(",")]
    except ValueError:
        sys.exit(f"--pose: not six numbers: {args.pose}")
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        sys.exit(f"--pose: need six finite numbers, got {args.pose}")
    scene = Scene(args.scene)
    start = pose_from_xyz_rpy(values)
    # The step from the pose to the truth in the part's frame: start * step = truth.
    step = np.linalg.inv(start) @ scene.truth
    rotation_vector = rotation_log(step[:3, :3])
    print("fraction  within_0.5mm  within_1mm  tukey_1.5mm  tukey_3mm  (fraction 0: the pose, 1: the truth)")
    for i in range(args.steps + 1):
        fraction = i / args.steps
        partial = np.eye(4)
        partial[:3, :3] = rotation_exp(rotation_vector * fraction)
        partial[:3, 3] = step[:3, 3] * fraction
        distances, _ = scene.residuals(start @ partial)
        print(
            f"{fraction:8.1f}  {int((distances < 5e-4).sum()):12d}  {int((distances < 1e-3).sum()):10d}"
            f"  {tukey_cost(distances, 0.0015) * 1e6:11.1f}  {tukey_cost(distances, 0.003) * 1e6:9.1f}"
        )
    for name, pose in (("pose", start), ("truth", scene.truth)):
        behind, in_front = sides(*scene.residuals(pose))
        print(f"{name}: {behind} points behind the surface, {in_front} in front (beyond a robust sigma)")


if __name__ == "__main__":
    main()
