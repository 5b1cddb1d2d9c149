#!/usr/bin/env python3
"""Runs an `agp bench` over a running Ray cluster, one Ray task per shard, then merges.

Starts nothing itself: it connects to the cluster at `--address` (`ray start --head` on one
machine, `ray start --address=HEAD:PORT` on the others), runs

    AGP bench <benchmark> <args...> --shard I/N --json OUT/part-I.json

as one task per shard I = 1..N (each task asks Ray for `--cpus-per-shard` CPUs), and, when
every shard succeeded, `AGP bench merge OUT/part-*.json --json OUT/merged.json`. The merged
JSON is what one `agp bench <benchmark> <args...>` over all the seeds writes, but for the
wall times. OUT must be a folder every node of the cluster reaches at the same path (a
shared filesystem), and AGP an absolute path that exists on every node.

Example (a local cluster):
    ray start --head --num-cpus 2 --include-dashboard=false
    python3 tools/sweep/ray_sweep.py --address auto --agp "$PWD/target/release/agp" \\
        --shards 4 --out sweep -- place --scenario triangle --episodes 5 --seeds 20
    ray stop
"""

import argparse
import json
import os
import subprocess
import sys
import time

import ray


@ray.remote
def run_shard(agp, bench_args, index, count, part, cwd):
    """One shard: `agp bench ... --shard index/count --json part`, in `cwd`."""
    cmd = [agp, "bench", *bench_args, "--shard", f"{index}/{count}", "--json", part]
    started = time.monotonic()
    proc = subprocess.run(
        cmd, cwd=cwd, stdin=subprocess.DEVNULL, capture_output=True, text=True
    )
    return {
        "index": index,
        "command": " ".join(cmd),
        "returncode": proc.returncode,
        "stdout": proc.stdout,
        "stderr": proc.stderr,
        "wall_s": time.monotonic() - started,
        "node": os.uname().nodename,
    }


def main():
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "--address",
        required=True,
        help="the running Ray cluster: HEAD:PORT, or `auto` for the one started on this machine",
    )
    parser.add_argument("--agp", required=True, help="absolute path of the `agp` binary")
    parser.add_argument("--shards", type=int, default=4, help="shards (Ray tasks), default 4")
    parser.add_argument(
        "--cpus-per-shard",
        type=float,
        default=1.0,
        help="CPUs Ray reserves for each shard, default 1",
    )
    parser.add_argument(
        "--out", required=True, help="folder for the parts and merged.json (shared by every node)"
    )
    parser.add_argument("--plot", help="also draw each seed's figures to this SVG (merge --plot)")
    parser.add_argument(
        "bench_args",
        nargs=argparse.REMAINDER,
        help="after `--`: the benchmark and its arguments, e.g. `place --scenario triangle --seeds 8` (no --shard, no --json)",
    )
    args = parser.parse_args()
    bench_args = args.bench_args[1:] if args.bench_args[:1] == ["--"] else args.bench_args
    if not bench_args:
        parser.error("give the benchmark after `--`, e.g. `-- place --seeds 8`")
    if any(a == "--shard" or a.startswith("--shard=") or a == "--json" or a.startswith("--json=") for a in bench_args):
        parser.error("the sweep sets --shard and --json itself")
    if not os.path.isabs(args.agp) or not os.access(args.agp, os.X_OK):
        parser.error(f"--agp {args.agp}: not an absolute path of an executable")
    if args.shards < 1:
        parser.error("--shards must be at least 1")
    out = os.path.abspath(args.out)
    os.makedirs(out, exist_ok=True)

    ray.init(address=args.address, logging_level="WARNING", log_to_driver=False)
    started = time.monotonic()
    parts = [os.path.join(out, f"part-{i}.json") for i in range(1, args.shards + 1)]
    for part in parts:
        if os.path.exists(part):
            os.remove(part)
    tasks = [
        run_shard.options(num_cpus=args.cpus_per_shard).remote(
            args.agp, bench_args, i, args.shards, part, out
        )
        for i, part in enumerate(parts, start=1)
    ]
    results = ray.get(tasks)
    sweep_s = time.monotonic() - started
    failed = [r for r in results if r["returncode"] != 0]
    for r in sorted(results, key=lambda r: r["index"]):
        print(
            f"shard {r['index']}/{args.shards} on {r['node']}: exit {r['returncode']}, {r['wall_s']:.1f} s",
            flush=True,
        )
    if failed:
        for r in failed:
            sys.stderr.write(f"shard {r['index']} failed: {r['command']}\n{r['stderr'][-4000:]}\n")
        return 1
    merged = os.path.join(out, "merged.json")
    cmd = [args.agp, "bench", "merge", *parts, "--json", merged]
    if args.plot:
        cmd += ["--plot", os.path.abspath(args.plot)]
    merge = subprocess.run(cmd, stdin=subprocess.DEVNULL)
    if merge.returncode != 0:
        sys.stderr.write(f"merge failed: {' '.join(cmd)}\n")
        return 1
    with open(os.path.join(out, "sweep.json"), "w") as f:
        json.dump(
            {
                "shards": args.shards,
                "bench_args": bench_args,
                "sweep_wall_s": sweep_s,
                "shard_wall_s": [r["wall_s"] for r in sorted(results, key=lambda r: r["index"])],
            },
            f,
            indent=2,
        )
    print(f"sweep: {args.shards} shards in {sweep_s:.1f} s; merged JSON {merged}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
