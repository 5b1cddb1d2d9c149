#!/usr/bin/env bash
# The wheel-level Python planner's lockstep throughput through all three processes (physics,
# estimator, `wheel_planner.py` with AGP_BENCH_STEPS: it answers every frame, wheels
# alternating), beside the Rust planner's on the same machine at the same moment (the
# affordance planner placing the triangle: steps = simulated time x 640 Hz, over its wall
# time). A benchmark, not a test: it prints the figures.
#
#   examples/python-planner/bench.sh [STEPS] [AG_FILE]
#
# Binaries from target/release (AGP_BIN to change; `cargo build --release --workspace
# --bins` first), the interpreter from .venv-ci (tools/setup.sh), the AG file by default
# results/triangle.ag, else the tests' cache.
set -euo pipefail
repo="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
bin="$(realpath "${AGP_BIN:-$repo/target/release}")"
steps="${1:-200000}"
ag="${2:-}"
for f in "$repo/results/triangle.ag" "$repo/target/debug/agp-test-cache/triangle.ag"; do
    [ -n "$ag" ] || { [ -f "$f" ] && ag="$f"; } || true
done
[ -n "$ag" ] && [ -f "$ag" ] || { echo "bench: no triangle.ag: run \`target/release/agp up\` once (it learns results/triangle.ag)" >&2; exit 1; }
[ -x "$bin/agp" ] || { echo "bench: no $bin/agp: run \`cargo build --release --workspace --bins\`" >&2; exit 1; }
[ -x "$repo/.venv-ci/bin/python" ] || { echo "bench: no .venv-ci: run \`tools/setup.sh\`" >&2; exit 1; }
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
mkdir -p "$tmp/results"
cp "$ag" "$tmp/results/triangle.ag"
printf '#!/bin/sh\nexec "%s" "$@"\n' "$repo/.venv-ci/bin/python" > "$tmp/python"
chmod +x "$tmp/python"
launch() { # name, planner exec, planner args (TOML list body)
    cat > "$tmp/$1.toml" <<TOML
instance = "bench-$1-$$"
scenario = "triangle"
results = "results"
[clock]
mode = "lockstep"
rate_hz = 640
[[process]]
name = "physics"
exec = "agp-physics"
[[process]]
name = "estimator"
exec = "agp-estimator"
args = ["--reuse"]
[[process]]
name = "planner"
exec = "$2"
args = [$3]
ends_run = true
TOML
}
launch python "$tmp/python" "\"$repo/examples/python-planner/wheel_planner.py\""
launch rust "$bin/agp-planner" '"--mode", "place", "--planner", "affordance"'
py="$(cd "$tmp" && AGP_BENCH_STEPS="$steps" "$bin/agp" up python.toml 2>&1 | grep 'steps/s' || true)"
rs="$(cd "$tmp" && "$bin/agp" up rust.toml 2>&1 | grep "planner \`affordance\`: .* after" || true)"
[ -n "$py" ] || { echo "bench: the Python run printed no figure" >&2; exit 1; }
py_rate="$(sed -E 's/.*\(([0-9]+) steps\/s\).*/\1/' <<<"$py")"
rs_rate="$(sed -E 's/.* ([0-9.]+) s simulated, ([0-9.]+) s wall.*/\1 \2/' <<<"$rs" | awk '{printf "%.0f", $1 * 640 / $2}')"
echo "bench: Python wheel-level planner: $py_rate steps/s ($py)"
echo "bench: Rust affordance planner:    $rs_rate steps/s ($rs)"
