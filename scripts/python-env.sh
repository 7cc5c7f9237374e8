#!/usr/bin/env bash
# Creates .venv with the third-party clients the interop tests and examples use: pyzmq (the
# thesis's messages over ZeroMQ) and ur-rtde (SDU Robotics' RTDE client, import names
# rtde_receive/rtde_control, which UR users run against real controllers). Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
UR_RTDE_VERSION=1.6.5
# Test binaries run this concurrently (cargo runs several test threads and processes). Without
# a lock, a second run sees a half-installed package, reinstalls it over the first one's files
# and a running interpreter that has mmapped the old .so dies with SIGBUS. One run at a time;
# the later ones then find everything installed and only check.
exec 9>.venv.lock
flock 9
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
if ! .venv/bin/python -c "import zmq" 2>/dev/null; then
    .venv/bin/python -m pip install --quiet --disable-pip-version-check pyzmq==26.2.0
fi
# Checked by version, so bumping the pin upgrades an existing venv. Wheel only: building ur_rtde
# from source needs Boost and a C++ toolchain, and 1.6.5 ships a manylinux wheel for CPython 3.11.
if ! .venv/bin/python -c "import importlib.metadata as m, sys; sys.exit(m.version('ur-rtde') != '$UR_RTDE_VERSION')" 2>/dev/null; then
    if ! .venv/bin/python -m pip install --quiet --disable-pip-version-check --only-binary=:all: \
        "ur-rtde==$UR_RTDE_VERSION"; then
        echo "python-env.sh: pip could not install ur-rtde==$UR_RTDE_VERSION (a manylinux wheel" \
            "for CPython 3.11 x86_64); is the package index reachable?" >&2
        exit 1
    fi
fi
.venv/bin/python -c "import zmq; print('python env ready: pyzmq', zmq.__version__)"
.venv/bin/python -c "import rtde_receive, importlib.metadata as m; print('python env ready: ur-rtde', m.version('ur-rtde'))"
