#!/usr/bin/env bash
# The Ray sweep against one process: starts a local single-node Ray cluster (the real
# engine), runs `agp bench place` over the pipeline in SHARDS shards through
# tools/sweep/ray_sweep.py, merges, runs the same seeds in one process, and checks that the
# two JSONs agree on every figure and every per-seed list (not on wall times, nor on each
# episode's `estimate`: the judge's count of the estimator's estimates over the pipeline
# depends on timing, and differs between two one-process runs as well). Stops the
# cluster whatever happens and leaves no file in /dev/shm.
#
# Environment (all optional):
#   AGP          the agp binary (default: target/debug/agp of this repository)
#   AGP_RAY_VENV a virtual environment with `ray` (default: .venv-ci, as .ci/run makes it)
#   AGP_AG       the triangle's AG file (default: learned here first, at seed 7)
#   SEEDS        seeds of the sweep (default 8), SHARDS shards (default 4)
#   KEEP         a folder to copy the JSONs and timings into
set -euo pipefail
repo="$(cd "$(dirname "$0")/../.." && pwd)"
agp="${AGP:-$repo/target/debug/agp}"
venv="${AGP_RAY_VENV:-$repo/.venv-ci}"
seeds="${SEEDS:-8}"
shards="${SHARDS:-4}"
ray="$venv/bin/ray"
python="$venv/bin/python"
[ -x "$agp" ] || { echo "no agp binary at $agp (cargo build --workspace --bins)" >&2; exit 2; }
[ -x "$ray" ] || { echo "no ray at $ray: $venv/bin/pip install ray==2.60.0 (as .ci/run does)" >&2; exit 2; }

# Short: Ray's socket paths live in its temp dir.
tmp="$(mktemp -d /tmp/agp-ray.XXXXXX)"
shm_before="$(ls /dev/shm | sort)"
started_ray=0
cleanup() {
    status=$?
    if [ "$started_ray" = 1 ]; then
        "$ray" stop >/dev/null 2>&1 || "$ray" stop --force >/dev/null 2>&1 || true
    fi
    rm -rf "$tmp"
    # Files of our runs (the benches' private pipelines, Ray's object store) left in /dev/shm.
    left="$(comm -13 <(echo "$shm_before") <(ls /dev/shm | sort) | grep -E 'bench-|ray|plasma' || true)"
    if [ -n "$left" ]; then
        echo "FAIL: files left in /dev/shm:" >&2
        echo "$left" >&2
        status=1
    fi
    exit "$status"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

ag="${AGP_AG:-}"
if [ -z "$ag" ]; then
    echo "== learning the triangle's AG (seed 7)"
    "$agp" bench learn --scenario triangle --seed 7 --out "$tmp/learn" >/dev/null
    ag="$tmp/learn/triangle.ag"
fi

port="$("$python" -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')"
echo "== ray start (local head, 2 CPUs, port $port)"
started_ray=1
RAY_USAGE_STATS_ENABLED=0 "$ray" start --head --num-cpus 2 --include-dashboard=false \
    --port "$port" --temp-dir "$tmp/ray" --disable-usage-stats >"$tmp/ray-start.log" 2>&1 \
    || { cat "$tmp/ray-start.log" >&2; exit 1; }

bench=(place --scenario triangle --planners affordance,baseline --episodes 1 --seeds "$seeds" --ag "$ag")
echo "== sweep: agp bench ${bench[*]} in $shards shards on Ray"
t0=$(date +%s.%N)
"$python" "$repo/tools/sweep/ray_sweep.py" --address "127.0.0.1:$port" --agp "$agp" \
    --shards "$shards" --out "$tmp/sweep" -- "${bench[@]}"
t1=$(date +%s.%N)
echo "== one process: agp bench ${bench[*]}"
(cd "$tmp" && "$agp" bench "${bench[@]}" --json "$tmp/one.json" >"$tmp/one.txt" 2>&1) \
    || { cat "$tmp/one.txt" >&2; exit 1; }
t2=$(date +%s.%N)

"$python" - "$tmp/sweep/merged.json" "$tmp/one.json" "$seeds" <<'PY'
import json, sys
merged, one, n = json.load(open(sys.argv[1])), json.load(open(sys.argv[2])), int(sys.argv[3])
# Wall times, and each episode's `estimate` (the estimates the judge's reader counted over
# the pipeline: timing-dependent, not a figure of the benchmark).
def strip(v):
    if isinstance(v, dict):
        return {k: strip(x) for k, x in v.items() if k not in ("wall_time_s", "estimate")}
    if isinstance(v, list):
        return [strip(x) for x in v]
    return v
def diff(a, b, path="$"):
    if type(a) != type(b):
        return [f"{path}: {a!r} != {b!r}"]
    if isinstance(a, dict):
        out = [f"{path}.{k}: only in one" for k in set(a) ^ set(b)]
        for k in set(a) & set(b):
            out += diff(a[k], b[k], f"{path}.{k}")
        return out
    if isinstance(a, list):
        if len(a) != len(b):
            return [f"{path}: {len(a)} items != {len(b)}"]
        return [d for i, (x, y) in enumerate(zip(a, b)) for d in diff(x, y, f"{path}[{i}]")]
    return [] if a == b else [f"{path}: {a!r} != {b!r}"]
d = diff(strip(merged), strip(one))
assert merged["seeds"] == one["seeds"] and len(one["seeds"]) == n, (merged["seeds"], one["seeds"])
assert [p["seed"] for p in merged["per_seed"]] == merged["seeds"]
assert "shard" not in merged
if d:
    print("FAIL: the merged sweep differs from one process:", *d[:20], sep="\n  ")
    sys.exit(1)
for name, p in one["planners"].items():
    print(f"  {name}: {p['episodes']} episodes, success {100 * p['success_rate']:.0f} %, "
          f"median position error {p['median_position_error_mm']:.1f} mm")
print("identical: every figure and every per-seed list (wall times aside)")
PY
sweep_s=$("$python" -c "print(round($t1 - $t0, 1))")
one_s=$("$python" -c "print(round($t2 - $t1, 1))")
printf 'wall time: sweep %.1f s (%s shards on Ray, merged), one process %.1f s\n' "$sweep_s" "$shards" "$one_s"
if [ -n "${KEEP:-}" ]; then
    mkdir -p "$KEEP"
    cp "$tmp/sweep/"*.json "$tmp/one.json" "$KEEP/"
    printf '{"sweep_s": %s, "one_process_s": %s}\n' "$sweep_s" "$one_s" >"$KEEP/timing.json"
fi
