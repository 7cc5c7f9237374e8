#!/usr/bin/env python3
"""Runs an `ips` binary's `align-cloud` on saved cad-scans scenes, one process a scene.

For builds the replay bench cannot reach: any commit whose `ips align-cloud` takes --cloud,
--mesh, --pose and --delta and prints --json with `pose.matrix` and `time_s` (the issue's
baseline fa44f0a has them, and so does main). Build the commit in a worktree of its own, then:

    python3 scripts/align-cloud-scenes.py --ips /tmp/old/target/release/ips \
        --scenes /tmp/setA50 --runs 3 [--local] [--json]

Each scene (a folder from `cad-scans --out`, or a folder of links to them) has `scene.json`
(the start's 4x4 matrix and delta), `truth.json`, the cloud and the mesh. The error is the
thesis's pose distance to the truth, the part's radius the largest distance of its distinct
vertices from their mean (as `Mesh::radius_m`); success is under 1 mm, as the replay bench
counts. The time is the alignment's own `time_s` (the process's start and the files' reading
are left out), the median of --runs runs a scene (the replay bench keeps a scene's fastest).

The start goes to `ips` as text (x, y, z, roll, pitch, yaw), which differs from the scene's
matrix in the last bits: a part whose twins score exactly alike (reported AMBIGUOUS, margin 0)
may then end at the other twin than the replay bench's.
"""

import argparse
import json
import math
import statistics
import struct
import subprocess
import sys
from pathlib import Path

SUCCESS_MM = 1.0


def read_stl_vertices(path):
    """Distinct vertices of a binary or ASCII STL."""
    data = path.read_bytes()
    vertices = set()
    if len(data) >= 84:
        count = struct.unpack_from("<I", data, 80)[0]
        if 84 + 50 * count == len(data):
            for i in range(count):
                base = 84 + 50 * i + 12
                for k in range(3):
                    vertices.add(struct.unpack_from("<3f", data, base + 12 * k))
            return vertices
    for line in data.decode("ascii", errors="replace").splitlines():
        words = line.split()
        if len(words) == 4 and words[0] == "vertex":
            vertices.add(tuple(float(w) for w in words[1:]))
    return vertices


def part_radius_m(mesh_path):
    vertices = read_stl_vertices(mesh_path)
    if not vertices:
        raise ValueError(f"{mesh_path}: no vertices read (only STL meshes are supported)")
    n = len(vertices)
    mean = [sum(v[a] for v in vertices) / n for a in range(3)]
    return max(math.dist(v, mean) for v in vertices)


def xyz_rpy(matrix):
    """x, y, z and roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll)) of a 4x4 matrix."""
    r = [row[:3] for row in matrix[:3]]
    pitch = math.asin(max(-1.0, min(1.0, -r[2][0])))
    roll = math.atan2(r[2][1], r[2][2])
    yaw = math.atan2(r[1][0], r[0][0])
    return [matrix[0][3], matrix[1][3], matrix[2][3], roll, pitch, yaw]


def pose_distance_m(a, b, radius_m):
    """The thesis's pose distance: the origin's shift and the turn between them times the radius."""
    shift = math.dist([a[i][3] for i in range(3)], [b[i][3] for i in range(3)])
    # The turn's angle from the trace of a^T b.
    trace = sum(a[k][i] * b[k][i] for i in range(3) for k in range(3))
    angle = math.acos(max(-1.0, min(1.0, (trace - 1.0) / 2.0)))
    return math.hypot(shift, angle * radius_m)


def align(ips, scene_dir, scene, local):
    command = [
        str(ips),
        "align-cloud",
        "--cloud",
        str(scene_dir / scene["cloud"]),
        "--mesh",
        str(scene_dir / scene["mesh"]),
        "--pose",
        ",".join(repr(v) for v in xyz_rpy(scene["start"])),
        "--delta",
        repr(scene["delta_m"]),
        "--json",
    ]
    if local:
        command.append("--local")
    done = subprocess.run(command, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        return None, done.stderr.strip().splitlines()[-1:] or ["no output"]
    return json.loads(done.stdout), None


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--ips", required=True, type=Path, help="the ips binary to run")
    parser.add_argument("--scenes", required=True, type=Path, help="folder of scene folders")
    parser.add_argument("--runs", type=int, default=1, help="runs a scene; the median time")
    parser.add_argument("--local", action="store_true", help="pass --local (the local stage)")
    parser.add_argument("--json", action="store_true", help="one JSON document")
    args = parser.parse_args()
    if args.runs < 1:
        parser.error("--runs needs at least 1")
    if not args.ips.is_file():
        parser.error(f"no ips binary at {args.ips}")
    scene_dirs = sorted(p for p in args.scenes.iterdir() if (p / "scene.json").is_file())
    if not scene_dirs:
        parser.error(f"no scene folders (with scene.json) in {args.scenes}")
    rows = []
    for index, scene_dir in enumerate(scene_dirs):
        scene = json.loads((scene_dir / "scene.json").read_text())
        truth = json.loads((scene_dir / "truth.json").read_text())
        radius_m = part_radius_m(scene_dir / scene["mesh"])
        times, error_mm, failure = [], math.nan, None
        for _ in range(args.runs):
            report, failure = align(args.ips, scene_dir, scene, args.local)
            if report is None:
                break
            times.append(report["time_s"])
            error_mm = 1e3 * pose_distance_m(report["pose"]["matrix"], truth, radius_m)
        rows.append(
            {
                "id": scene["id"],
                "part": scene.get("part"),
                "error_mm": error_mm,
                "succeeded": error_mm < SUCCESS_MM,
                "time_s": statistics.median(times) if times else None,
                "failure": failure,
            }
        )
        print(f"\r{index + 1}/{len(scene_dirs)} scenes", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)
    times = [r["time_s"] for r in rows if r["time_s"] is not None]
    summary = {
        "scenes": len(rows),
        "succeeded": sum(r["succeeded"] for r in rows),
        "failed_to_run": sum(r["failure"] is not None for r in rows),
        "median_time_s": statistics.median(times) if times else None,
    }
    if args.json:
        print(json.dumps({"summary": summary, "scenes": rows}))
        return
    median = summary["median_time_s"]
    print(
        f"{args.scenes}: {summary['succeeded']}/{summary['scenes']} within {SUCCESS_MM} mm, "
        f"median {median * 1e3:.1f} ms" if median is not None else "no alignment ran"
    )
    for row in rows:
        if row["failure"]:
            print(f"  scene {row['id']}: {row['failure'][0]}")


if __name__ == "__main__":
    main()
