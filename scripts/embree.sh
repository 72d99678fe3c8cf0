#!/usr/bin/env bash
# Makes Embree 4 available to the build, only when it is missing. The build (build.rs) looks in
# this order: $EMBREE_DIR, the system (/usr/include/embree4 with libembree4, as Debian trixie's
# libembree-dev installs them), then .deps/embree, which this script fills on Debian bookworm:
# - the library: Intel's libembree4 4.4.0 and the oneTBB it was built against, from the PyPI
#   wheel `embreex` 4.4.0.post1 (manylinux_2_28, so it runs on bookworm's glibc 2.36);
# - the headers: Debian's own libembree-dev (4.4.x from forky, else 4.3.x from trixie: the two
#   declare the same ray, hit and argument structs), fetched with `apt-get download` through a
#   throwaway sources list and unpacked with dpkg-deb, never installed (Debian's libembree4-4
#   needs glibc 2.38 and cannot be installed on bookworm).
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dest="$root/.deps/embree"
wheel_version=4.4.0.post1
[ -n "${EMBREE_DIR:-}" ] && exit 0
if [ -f /usr/include/embree4/rtcore.h ] && ldconfig -p 2>/dev/null | grep -q 'libembree4\.so '; then
  exit 0
fi
if [ -f "$dest/include/embree4/rtcore.h" ] && [ -e "$dest/lib/libembree4.so" ]; then
  exit 0
fi
echo "setup: fetching Embree 4 (the embreex $wheel_version wheel, Debian's libembree-dev headers) into $dest" >&2
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$dest/lib" "$dest/include"

python3 -m pip download --quiet --no-deps --only-binary=:all: --dest "$tmp" \
  --platform manylinux_2_28_x86_64 --python-version 3.11 --implementation cp --abi cp311 \
  "embreex==$wheel_version"
python3 - "$tmp"/embreex-*.whl "$dest/lib" <<'PY'
import os, re, shutil, sys, zipfile
wheel, out = sys.argv[1], sys.argv[2]
wanted = re.compile(r"^embreex\.libs/(libembree4-[0-9a-f]+\.so\.4|libtbb-[0-9a-f]+\.so\.12)$")
found = []
with zipfile.ZipFile(wheel) as z:
    for name in z.namelist():
        m = wanted.match(name)
        if not m:
            continue
        with z.open(name) as src, open(os.path.join(out, m.group(1)), "wb") as dst:
            shutil.copyfileobj(src, dst)
        os.chmod(os.path.join(out, m.group(1)), 0o755)
        found.append(m.group(1))
if len([f for f in found if f.startswith("libembree4")]) != 1 or len(found) != 2:
    sys.exit(f"embree.sh: the wheel holds {found}, not one libembree4 and one libtbb")
PY
# The name the linker looks for (-lembree4); the loader looks for the library's SONAME, the file.
ln -sf "$(basename "$(ls "$dest"/lib/libembree4-*.so.4)")" "$dest/lib/libembree4.so"

apt="$tmp/apt"
mkdir -p "$apt/lists/partial" "$apt/cache/archives/partial"
keyring=/usr/share/keyrings/debian-archive-keyring.gpg
cat > "$apt/sources.list" <<EOF
deb [signed-by=$keyring] http://deb.debian.org/debian forky main
deb [signed-by=$keyring] http://deb.debian.org/debian trixie main
EOF
opts=(-o "Dir::Etc::SourceList=$apt/sources.list" -o Dir::Etc::SourceParts=/dev/null
      -o "Dir::State::Lists=$apt/lists" -o "Dir::Cache=$apt/cache" -o Debug::NoLocking=1
      -o APT::Sandbox::User=root)
apt-get "${opts[@]}" -qq update
version=$(apt-cache "${opts[@]}" madison libembree-dev | awk '{print $3}' | grep -E '^4\.4\.' | head -1 || true)
[ -n "$version" ] || version=$(apt-cache "${opts[@]}" madison libembree-dev | awk '{print $3}' | grep -E '^4\.3\.' | head -1 || true)
if [ -z "$version" ]; then
  echo "embree.sh: no libembree-dev 4.3 or 4.4 in Debian trixie or forky; set EMBREE_DIR instead" >&2
  exit 1
fi
(cd "$tmp" && apt-get "${opts[@]}" -qq download "libembree-dev=$version")
dpkg-deb -x "$tmp"/libembree-dev_*.deb "$tmp/deb"
rm -rf "$dest/include/embree4"
cp -r "$tmp/deb/usr/include/embree4" "$dest/include/embree4"
echo "setup: Embree 4 headers from Debian's libembree-dev $version" >&2
