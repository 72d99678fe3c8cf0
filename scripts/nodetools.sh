#!/usr/bin/env bash
# Installs the Node tools the tests use into .deps/nodetools (outside git), only when missing:
# the Khronos glTF validator, which checks every .glb `relume export` writes, and obj2gltf
# (Cesium's OBJ converter), a real glTF writer whose output relume must read (tests/gltf.rs),
# and ws, the WebSocket the JavaScript client's tests use where Node has none of its own
# (Debian's Node 18; tests/clients.rs). Node.js and npm come from Debian when absent.
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dest="$root/.deps/nodetools"
version=2.0.0-dev.3.10
obj2gltf=3.2.0
ws=8.18.3
installed() { node -p "require('$dest/node_modules/$1/package.json').version" 2>/dev/null; }
if [ "$(installed gltf-validator)" = "$version" ] && [ "$(installed obj2gltf)" = "$obj2gltf" ] \
  && [ "$(installed ws)" = "$ws" ]; then
  exit 0
fi
if ! command -v npm >/dev/null; then
  echo "setup: installing nodejs and npm" >&2
  export DEBIAN_FRONTEND=noninteractive
  sudo_cmd=""
  [ "$(id -u)" -eq 0 ] || sudo_cmd="sudo"
  $sudo_cmd apt-get update -qq
  $sudo_cmd apt-get install -y -qq nodejs npm >/dev/null
fi
echo "setup: installing gltf-validator $version, obj2gltf $obj2gltf and ws $ws into $dest" >&2
rm -rf "$dest"
mkdir -p "$dest"
npm install --silent --no-audit --no-fund --prefix "$dest" "gltf-validator@$version" "obj2gltf@$obj2gltf" "ws@$ws"
