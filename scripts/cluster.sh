#!/usr/bin/env bash
# Three relume nodes behind HAProxy on loopback, to try sticky routing, draining and
# `relume migrate` by hand (deploy/haproxy/relume.cfg; README, "Scaling out"):
#
#   bash scripts/cluster.sh [NODES] [BASE_PORT]     NODES 2 or 3 (default 3), BASE_PORT 8090
#
# The proxy listens on BASE_PORT and node relume-I on BASE_PORT+1+I. Ctrl-C stops them all.
# Try: create sessions through the proxy, read X-Relume-Node, then
#   kill -TERM <pid of relume-0>      (printed below) and
#   target/release/relume migrate --from http://127.0.0.1:8091 --to http://127.0.0.1:8090 --all
set -euo pipefail
cd "$(dirname "$0")/.."
nodes=${1:-3}
base=${2:-8090}
case "$nodes" in 2|3) ;; *) echo "cluster.sh: NODES is 2 or 3 (relume.cfg names three nodes)" >&2; exit 2 ;; esac
scripts/setup.sh scripts/packages.txt <(echo haproxy)
export PATH="$HOME/.cargo/bin:$PATH"
cargo build --release --locked
pids=()
cleanup() {
  trap - EXIT INT TERM
  # SIGINT: the nodes stop at once (SIGTERM would drain them first).
  kill -INT "${pids[@]}" 2>/dev/null || true
  wait 2>/dev/null || true
}
trap cleanup EXIT INT TERM
threads=$(( $(nproc) / nodes )); [ "$threads" -ge 1 ] || threads=1
export RELUME_PROXY_BIND="127.0.0.1:$base" RELUME_NODE_MAP=deploy/haproxy/nodes.map
for i in 0 1 2; do
  export "RELUME_NODE_$i=127.0.0.1:$((base + 1 + i))"
done
for ((i = 0; i < nodes; i++)); do
  target/release/relume serve --node "relume-$i" --addr "127.0.0.1:$((base + 1 + i))" \
    --threads "$threads" --drain-grace 60 &
  pids+=($!)
  echo "cluster: node relume-$i on http://127.0.0.1:$((base + 1 + i))/ (pid $!)" >&2
done
haproxy -db -f deploy/haproxy/relume.cfg &
proxy=$!
pids+=("$proxy")
echo "cluster: HAProxy on http://127.0.0.1:$base/ (pid $proxy); Ctrl-C stops everything" >&2
# Nodes may come and go (a drained node exits); the cluster lasts as long as the proxy.
wait "$proxy"
