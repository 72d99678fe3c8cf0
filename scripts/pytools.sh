#!/usr/bin/env bash
# Installs the Python packages the tests use into .deps/pytools (outside git), only when the
# pinned set is not there yet: kubernetes-validate, which checks deploy/kubernetes/ against the
# Kubernetes API schemas it carries (offline once installed; tests/deploy.rs), and what the
# Python client (clients/python) needs to run its tests (tests/clients.rs). `pip
# --target` leaves the system's Python untouched.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dest="$root/.deps/pytools"
packages=(
  "kubernetes-validate==1.37.0"
  "httpx==0.28.1"
  "websockets==15.0.1"
  "numpy==2.2.6"
  "pytest==8.4.2"
  "pyyaml==6.0.2"
)
stamp="$dest/.relume-packages"
if [ -f "$stamp" ] && [ "$(cat "$stamp")" = "${packages[*]}" ]; then
  exit 0
fi
echo "setup: installing ${packages[*]} into $dest" >&2
rm -rf "$dest"
python3 -m pip install --quiet --disable-pip-version-check --no-warn-script-location \
  --target "$dest" "${packages[@]}"
echo "${packages[*]}" > "$stamp"
