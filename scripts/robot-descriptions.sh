#!/usr/bin/env bash
# Fetches third-party robot descriptions with real CAD meshes for the robot fit's trials and its
# bench, beside the ABB IRB 1600 of ../shared/data. The shipped UR10 and iiwa14 (robots/*.urdf)
# are drawn from primitives (cylinders and capsules, 256-512 triangles a link): a fit measured
# on them says nothing of a robot whose links are CAD. This one is Universal Robots' UR10 as
# ROS-Industrial's ur_description describes it (license BSD, as the wheel's README of it says),
# from the PyPI wheel example-robot-data 6.0.0 (the wheel of scripts/unseen-parts.sh; its UR5,
# not this UR10, is a set of parts there). Its collision meshes are used: the visual ones are
# Collada, which the project does not read. The URDF is written with its seven <visual> elements
# left out, so that each link is its collision mesh; nothing else in it is changed.
#
# Written, checked by SHA-256, under OUT (default target/robot-descriptions); nothing is copied
# into the repository:
#   OUT/example-robot-data/robots/ur_description/meshes/ur10/collision/*.stl
#   OUT/example-robot-data/robots/ur_description/urdf/ur10_collision.urdf
#
#   bash scripts/robot-descriptions.sh [OUT]
#   target/release/ips trials --urdf OUT/example-robot-data/robots/ur_description/urdf/ur10_collision.urdf \
#       --package-dir example-robot-data=OUT/example-robot-data \
#       --home 0,-1.5707963,1.5707963,-1.5707963,-1.5707963,0 --deltas 50,100 --trials 10 \
#       --hierarchical-only
#   EXAMPLE_ROBOT_DATA_DIR=OUT/example-robot-data cargo bench -p align-core --bench articulated_starts
#
# Idempotent: files already in place with the right hash are kept.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-target/robot-descriptions}"
DOWNLOADS="target/unseen-parts-wheel"
mkdir -p "$OUT" "$DOWNLOADS"
WHEEL_PREFIX="example_robot_data-6.0.0-"
if ! ls "$DOWNLOADS"/"$WHEEL_PREFIX"*.whl >/dev/null 2>&1; then
    python3 -m pip download --quiet --disable-pip-version-check --no-deps \
        "example-robot-data==6.0.0" -d "$DOWNLOADS"
fi
WHEEL="$(ls "$DOWNLOADS"/"$WHEEL_PREFIX"*.whl | head -1)"
python3 - "$WHEEL" "$OUT" <<'EOF'
import hashlib, os, re, sys, zipfile

wheel, out = sys.argv[1], sys.argv[2]
inside = "cmeel.prefix/share/example-robot-data/"
description = "robots/ur_description/"
# Path under the description, SHA-256 of the file in the wheel.
FILES = {
    "README.md": "95770dc3fc9889d34fa5569ce4c4fa231c163c055c5aa322402413332f832a50",
    "meshes/ur10/collision/base.stl": "c2049e55f6ddbd827d89342c5e3d277b62493db681d28f44ca555db1a288e2cf",
    "meshes/ur10/collision/forearm.stl": "dc90009a4863cbdb350f2a40e40ca25db0ddba1eb6811e0e0d3c914293f365d0",
    "meshes/ur10/collision/shoulder.stl": "8f2b5085694ffb5208da1099bd9c5b381155a82c5fec1bc72bb050f3c30c0ece",
    "meshes/ur10/collision/upperarm.stl": "c84a410a76cf8d25e1d830d9033a4e501fb16baeb2bf0116367a0cdb98c75fbb",
    "meshes/ur10/collision/wrist1.stl": "c33737b72a82d61a9d4b1c3abb75eab8349e935c60340f59b7d1ed004ac16142",
    "meshes/ur10/collision/wrist2.stl": "8070916b9042dce67c85fccaa94fa60308722945405a58abc6070c1bb8de9bb9",
    "meshes/ur10/collision/wrist3.stl": "07401ab0442bb02772aca606889146ff5fc0b30c8f037e4b2878cfefb1b7c443",
    "urdf/ur10_robot.urdf": "16e4d9c85f01d2533fa219d28e2e5a2ce93836be7afaf243b46be4ba76e0d4ea",
}


def write(path, data):
    if os.path.exists(path) and open(path, "rb").read() == data:
        return
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path, "wb") as handle:
        handle.write(data)


with zipfile.ZipFile(wheel) as archive:
    for name, expected in FILES.items():
        data = archive.read(inside + description + name)
        if hashlib.sha256(data).hexdigest() != expected:
            sys.exit(f"robot-descriptions: {name} in {wheel} does not have the expected SHA-256")
        if name.endswith(".urdf"):
            continue
        write(os.path.join(out, "example-robot-data", description, name), data)
    urdf = archive.read(inside + description + "urdf/ur10_robot.urdf").decode("utf-8")
visuals = len(re.findall(r"<visual>", urdf))
collision_only = re.sub(r"\s*<visual>.*?</visual>", "", urdf, flags=re.S)
if visuals != 7 or "<visual" in collision_only:
    sys.exit(f"robot-descriptions: expected 7 <visual> elements in ur10_robot.urdf, found {visuals}")
target = os.path.join(out, "example-robot-data", description, "urdf/ur10_collision.urdf")
write(target, collision_only.encode("utf-8"))
print(f"robot-descriptions: the UR10 (collision meshes) in {os.path.join(out, 'example-robot-data')}")
EOF
