#!/usr/bin/env bash
# Installs the Python tools the tests use into .deps/pytools (outside git), only when missing:
# kubernetes-validate, which checks deploy/kubernetes/ against the Kubernetes API schemas it
# carries (offline once installed; tests/deploy.rs). `pip --target` leaves the system's
# Python untouched.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dest="$root/.deps/pytools"
version=1.37.0
if PYTHONPATH="$dest" python3 -c "import kubernetes_validate, sys; sys.exit(kubernetes_validate.__version__ != '$version')" 2>/dev/null; then
  exit 0
fi
echo "setup: installing kubernetes-validate $version into $dest" >&2
rm -rf "$dest"
python3 -m pip install --quiet --disable-pip-version-check --no-warn-script-location \
  --target "$dest" "kubernetes-validate==$version"
