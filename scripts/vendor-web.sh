#!/usr/bin/env bash
# Re-fetches the operator page's vendored three.js from the npm registry (npm pack, no install,
# no build step): the page must work with no network beyond `ips serve`, so the module is
# embedded in the binary from crates/operator-page/assets/vendor/. Bump THREE_VERSION here and in
# that folder's README together.
set -euo pipefail
cd "$(dirname "$0")/.."
THREE_VERSION=0.170.0
vendor=crates/operator-page/assets/vendor
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
(cd "$work" && npm pack --silent "three@$THREE_VERSION" >/dev/null && tar xzf "three-$THREE_VERSION.tgz")
cp "$work/package/build/three.module.min.js" "$vendor/three.module.min.js"
cp "$work/package/LICENSE" "$vendor/three.LICENSE"
echo "vendored three@$THREE_VERSION into $vendor"
