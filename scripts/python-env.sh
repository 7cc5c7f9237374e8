#!/usr/bin/env bash
# Creates .venv with the third-party clients the interop tests and examples use: pyzmq (the
# thesis's messages over ZeroMQ). Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
if [ ! -x .venv/bin/python ]; then
    python3 -m venv .venv
fi
if ! .venv/bin/python -c "import zmq" 2>/dev/null; then
    .venv/bin/python -m pip install --quiet --disable-pip-version-check pyzmq==26.2.0
fi
.venv/bin/python -c "import zmq; print('python env ready: pyzmq', zmq.__version__)"
