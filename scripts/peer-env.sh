#!/usr/bin/env bash
# Installs the peers that the CAD scan trials (cad-scans, docs/cad-scan-trials.md) run in the same
# run as ips: Open3D (point-to-plane ICP) and small_gicp (GICP), in the project's venv .venv (made
# by scripts/python-env.sh), and Debian's libusb-1.0-0, which Open3D's shared library links
# against (only when it is missing; CI runs as root). Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
# open3d-cpu is Open3D's own CPU-only build of the same library (one fifth of the download of
# the CUDA one; this machine has no GPU).
OPEN3D_VERSION=0.20.0
SMALL_GICP_VERSION=1.0.1
if ! ldconfig -p | grep -q 'libusb-1.0.so.0'; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
fi
bash scripts/python-env.sh >/dev/null
# Same lock as python-env.sh: a second run must not reinstall over a running interpreter's files.
exec 9>.venv.lock
flock 9
installed() {
    .venv/bin/python -c "import importlib.metadata as m, sys; sys.exit(m.version('$1') != '$2')" 2>/dev/null
}
if ! installed open3d-cpu "$OPEN3D_VERSION"; then
    .venv/bin/python -m pip install --quiet --disable-pip-version-check --only-binary=:all: \
        "open3d-cpu==$OPEN3D_VERSION"
fi
if ! installed small_gicp "$SMALL_GICP_VERSION"; then
    .venv/bin/python -m pip install --quiet --disable-pip-version-check --only-binary=:all: \
        "small_gicp==$SMALL_GICP_VERSION"
fi
.venv/bin/python -c "import open3d, small_gicp, importlib.metadata as m; print('peer env ready: open3d', open3d.__version__, '| small_gicp', m.version('small_gicp'))"
