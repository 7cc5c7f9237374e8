#!/usr/bin/env bash
# Installs what the operator page's browser test needs: Debian's chromium and chromium-driver
# (only when /usr/bin/chromium is missing; CI runs as root) and selenium in the project's venv
# (after scripts/python-env.sh made it). Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
SELENIUM_VERSION=4.27.1
if [ ! -x /usr/bin/chromium ] || [ ! -x /usr/bin/chromedriver ]; then
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null
fi
bash scripts/python-env.sh >/dev/null
exec 9>.venv.lock
flock 9
if ! .venv/bin/python -c "import importlib.metadata as m, sys; sys.exit(m.version('selenium') != '$SELENIUM_VERSION')" 2>/dev/null; then
    .venv/bin/python -m pip install --quiet --disable-pip-version-check "selenium==$SELENIUM_VERSION"
fi
echo "browser env ready: $(/usr/bin/chromium --version 2>/dev/null), selenium $SELENIUM_VERSION"
