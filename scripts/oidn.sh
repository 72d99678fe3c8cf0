#!/usr/bin/env bash
# Unpacks Intel's official Linux build of Open Image Denoise 2.5.1 into .deps/oidn/lib (outside
# git), only when it is missing. Debian bookworm has no OIDN package; the PyPI wheel `pyoidn`
# 2.5.1.0 carries Intel's build: libOpenImageDenoise, its core and CPU device modules, and the
# TBB they were built against. Only the system libstdc++ is needed besides. The build reads
# OIDN_DIR (.cargo/config.toml) and sets an rpath to this folder (build.rs).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dest="$root/.deps/oidn"
version=2.5.1
wheel_version=2.5.1.0
libs=(libOpenImageDenoise.so.$version libOpenImageDenoise_core.so.$version
      libOpenImageDenoise_device_cpu.so.$version libtbb.so.12)
have=1
for lib in "${libs[@]}"; do [ -f "$dest/lib/$lib" ] || have=0; done
[ $have -eq 1 ] && exit 0
echo "setup: fetching Open Image Denoise $version (the pyoidn $wheel_version wheel) into $dest" >&2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
python3 -m pip download --quiet --no-deps --only-binary=:all: --dest "$tmp" \
  --platform manylinux2014_x86_64 "pyoidn==$wheel_version"
mkdir -p "$dest/lib"
python3 - "$tmp"/pyoidn-*.whl "$dest/lib" "${libs[@]}" <<'PY'
import sys, zipfile, os, shutil
wheel, out, names = sys.argv[1], sys.argv[2], sys.argv[3:]
with zipfile.ZipFile(wheel) as z:
    for name in names:
        with z.open(f"pyoidn/oidn/lib/{name}") as src, open(os.path.join(out, name), "wb") as dst:
            shutil.copyfileobj(src, dst)
        os.chmod(os.path.join(out, name), 0o755)
PY
# The names the linker (-lOpenImageDenoise) and the loader (the SONAME) look for.
ln -sf "libOpenImageDenoise.so.$version" "$dest/lib/libOpenImageDenoise.so.2"
ln -sf "libOpenImageDenoise.so.2" "$dest/lib/libOpenImageDenoise.so"
