#!/usr/bin/env python3
"""The peers of the CAD scan trials (crates/cad-scans), on the scenes the Rust runner wrote.

For each scene.json (cloud.ply and part.stl beside it, the start pose world_from_part and the
bound delta) it prints one JSON line on stdout:
  {"id": N, "open3d": {"pose": 4x4, "time_s": t}, "small_gicp": {"pose": 4x4, "time_s": t}}
or {"error": "..."} for a method that fails. Progress goes to stderr. The runner keeps the truth
and scores every method the same way.

Both peers get what ips gets: the mesh, the scan, the start and delta. Both crop the scan to the
part's box at the start grown by delta (as ips's cut-off filter does), then run coarse to fine:
the correspondence distance starts at delta (at most 0.3 m, at least 2 cm) and halves each
stage down to 1 cm, the voxel a third of it (5 mm to 2 cm), then a last stage at 5 mm with a
2.5 mm voxel. Open3D's scan normals come from a 15 mm neighbourhood at least (the rays are
3-10 mm apart). These settings were chosen on the 50 mm scenes of a first run (seed 20) to give
the peers their best precision: Open3D went from 14/40 to 26/40 with them. The time covers the crop, the
downsampling, normals and the registration; the model's sampling is done once before, as ips
builds its mesh before its clock starts.

Set up by scripts/peer-env.sh (Open3D's CPU build and small_gicp in .venv).
"""

import argparse
import json
import os
import sys
import time

import numpy as np
import open3d as o3d
import small_gicp

MODEL_SPACING_M = 0.003
MAX_MODEL_POINTS = 30000
# The scans' rays are 3-10 mm apart: a normal needs a neighbourhood of a few of them.
NORMAL_RADIUS_M = 0.015


def stages(delta_m):
    """(correspondence distance, voxel) per stage, coarse to fine."""
    distance = min(max(delta_m, 0.02), 0.3)
    out = []
    while distance > 0.01:
        out.append((distance, min(max(distance / 3.0, 0.005), 0.02)))
        distance = max(distance / 2.0, 0.01)
    # The fine end: a 5 mm voxel's centroids sit off the surface at edges by a millimetre or
    # so, which the 1 mm success bar notices; the last stages keep (nearly) every scan point.
    return out + [(0.01, 0.005), (0.005, 0.0025)]


def model_points(mesh_path):
    mesh = o3d.io.read_triangle_mesh(mesh_path)
    area = mesh.get_surface_area()
    count = int(min(max(area / MODEL_SPACING_M**2, 2000), MAX_MODEL_POINTS))
    cloud = mesh.sample_points_uniformly(number_of_points=count, use_triangle_normal=True)
    return cloud


def crop(points, model, start, delta_m):
    world = (start[:3, :3] @ model.T).T + start[:3, 3]
    low, high = world.min(axis=0) - delta_m, world.max(axis=0) + delta_m
    inside = np.all((points >= low) & (points <= high), axis=1)
    return points[inside]


def run_open3d(points, model_cloud, start, delta_m, threads):
    del threads  # Open3D's OpenMP uses every core (OMP_NUM_THREADS, set by main).
    started = time.perf_counter()
    model = np.asarray(model_cloud.points)
    target = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(crop(points, model, start, delta_m)))
    if len(target.points) < 10:
        return {"error": f"only {len(target.points)} scan points near the start", "time_s": time.perf_counter() - started}
    pose = start.copy()
    for distance, voxel in stages(delta_m):
        target_down = target.voxel_down_sample(voxel)
        target_down.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=max(2.5 * voxel, NORMAL_RADIUS_M), max_nn=30))
        source_down = model_cloud.voxel_down_sample(voxel)
        loss = o3d.pipelines.registration.TukeyLoss(k=distance)
        result = o3d.pipelines.registration.registration_icp(
            source_down,
            target_down,
            distance,
            pose,
            o3d.pipelines.registration.TransformationEstimationPointToPlane(loss),
            o3d.pipelines.registration.ICPConvergenceCriteria(
                relative_fitness=1e-7, relative_rmse=1e-7, max_iteration=50
            ),
        )
        pose = result.transformation
    return {"pose": pose.tolist(), "time_s": time.perf_counter() - started}


def run_small_gicp(points, model_cloud, start, delta_m, threads):
    started = time.perf_counter()
    model = np.asarray(model_cloud.points)
    target = crop(points, model, start, delta_m)
    if len(target) < 10:
        return {"error": f"only {len(target)} scan points near the start", "time_s": time.perf_counter() - started}
    pose = start.copy()
    for distance, voxel in stages(delta_m):
        result = small_gicp.align(
            target,
            model,
            pose,
            registration_type="GICP",
            downsampling_resolution=voxel,
            max_correspondence_distance=distance,
            num_threads=threads,
            max_iterations=50,
            translation_epsilon=1e-5,
            rotation_epsilon=1e-5,
        )
        pose = result.T_target_source
    return {"pose": np.asarray(pose).tolist(), "time_s": time.perf_counter() - started}


def main():
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--manifest", required=True, help="JSON list of scene.json paths")
    parser.add_argument("--threads", type=int, default=2, help="threads per peer")
    args = parser.parse_args()
    with open(args.manifest) as f:
        scenes = json.load(f)
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    for index, scene_path in enumerate(scenes):
        with open(scene_path) as f:
            scene = json.load(f)
        folder = os.path.dirname(scene_path)
        cloud = o3d.io.read_point_cloud(os.path.join(folder, scene["cloud"]))
        points = np.asarray(cloud.points)
        model_cloud = model_points(os.path.join(folder, scene["mesh"]))
        start = np.array(scene["start"], dtype=float)
        line = {"id": scene["id"]}
        for name, run in (("open3d", run_open3d), ("small_gicp", run_small_gicp)):
            try:
                line[name] = run(points, model_cloud, start, scene["delta_m"], args.threads)
            except Exception as error:  # A peer's failure is its result, not the run's end.
                line[name] = {"error": f"{type(error).__name__}: {error}"}
        print(json.dumps(line), flush=True)
        print(f"\rpeers: aligned {index + 1}/{len(scenes)}", end="", file=sys.stderr, flush=True)
    print(file=sys.stderr)


if __name__ == "__main__":
    main()
