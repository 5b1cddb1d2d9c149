#!/usr/bin/env python3
"""`agp profile` across a bridge, mutual TLS beside plain TCP, repeated: each bridged hop
against the link's Zenoh floor measured in the same run.

    python3 tools/bench_bridge_profile.py [--bin target/release] [--rounds 5] [--seconds 5]
                                          [--floor-seconds 2] [--ag results/triangle.ag]
                                          [--out results/bridge-profile] [--against DIR] [--trace]
                                          [--vary-env K=V] [--env K=V]

Each round runs, for each transport (TLS, then plain TCP): two lockstep live sessions on
this machine joined over the loopback by `agp bridge` (physics and the estimator in the
robot's instance, the affordance planner serving goals in the other), a placement goal,
then `agp profile --instance <robot's> --json`, then `agp down` of both. The profile samples
the pipeline, then with the robot's pipeline paused runs the iceoryx2 floor and the link's
floor (a bare Zenoh ping-pong between two `agp` processes on the bridge's transport), and
sets each bridged hop (estimator->planner, planner->physics) against the link floor's p50.

Prints one line per run and, at the end, the medians over the rounds per transport, with
the machine's load average (1 min) beside them, each round's ratios, and (--trace) the
medians of where the hops' time went. JSON of every run goes under --out.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
BRIDGED = ["estimator->planner", "planner->physics"]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


ENV = dict(os.environ)


def agp(bin_dir: Path, *args: str, check: bool = True, timeout: float = 120) -> subprocess.CompletedProcess:
    r = subprocess.run([str(bin_dir / "agp"), *args], capture_output=True, text=True, timeout=timeout, env=ENV)
    if check and r.returncode != 0:
        sys.exit(f"bench_bridge_profile: `agp {' '.join(args)}` exited {r.returncode}:\n{r.stdout}\n{r.stderr}")
    return r


def launch_files(out: Path, tag: str, ag: Path, endpoint: str, security: str) -> tuple[Path, Path, str, str]:
    robot, planner = f"bpr{tag}-{os.getpid() % 100000}", f"bpp{tag}-{os.getpid() % 100000}"
    r = out / f"robot-{tag}.toml"
    p = out / f"planner-{tag}.toml"
    r.write_text(
        f'instance = "{robot}"\nscenario = "triangle"\nresults = "{out}"\n\n[clock]\nmode = "lockstep"\n\n'
        f'[[process]]\nname = "physics"\nexec = "agp-physics"\n\n'
        f'[[process]]\nname = "estimator"\nexec = "agp-estimator"\nargs = ["--load", "{ag}"]\n\n'
        f'[[process]]\nname = "planner"\nremote = {{ role = "planner", listen = "{endpoint}", {security} }}\n'
    )
    p.write_text(
        f'instance = "{planner}"\nscenario = "triangle"\nresults = "{out}"\n\n[clock]\nmode = "lockstep"\n\n'
        f'[[process]]\nname = "robot"\nremote = {{ role = "robot", connect = "{endpoint}", {security} }}\n\n'
        f'[[process]]\nname = "planner"\nexec = "agp-planner"\nargs = ["--mode", "serve", "--planner", "affordance"]\n'
    )
    return r, p, robot, planner


def trace_lines(out: Path, *instances: str) -> list[str]:
    """The bridges' trace lines (`AGP_BRIDGE_TRACE`) of the instances' logs, as each bridge said
    them when it stopped."""
    lines = []
    for name in instances:
        log = out / f"agp-up-{name}.log"
        if log.exists():
            lines += [l.strip() for l in log.read_text(errors="replace").splitlines() if "agp bridge trace" in l]
    return lines


def one_run(bin_dir: Path, out: Path, ag: Path, keys: Path, tls: bool, k: int, args) -> dict:
    tag = "tls" if tls else "tcp"
    port = free_port()
    endpoint = f"{tag}/127.0.0.1:{port}"
    security = f'tls = "{keys}"' if tls else "insecure = true"
    r, p, robot, planner = launch_files(out, tag, ag, endpoint, security)
    agp(bin_dir, "up", str(r), "--detach")
    try:
        agp(bin_dir, "up", str(p), "--detach")
        try:
            agp(bin_dir, "goal", "--instance", robot, "--place", "300", "150", "90")
            time.sleep(args.settle)
            path = out / f"profile-{tag}-{k}.json"
            prof = agp(
                bin_dir, "profile", "--instance", robot, "--seconds", str(args.seconds),
                "--floor-seconds", str(args.floor_seconds), "--json", str(path),
            )
            (out / f"profile-{tag}-{k}.txt").write_text(prof.stdout)
            result = json.loads(path.read_text())
        finally:
            agp(bin_dir, "down", "--instance", planner, check=False)
    finally:
        agp(bin_dir, "down", "--instance", robot, check=False)
    if args.trace:
        lines = trace_lines(out, robot, planner)
        for l in lines:
            print(f"  {tag}: {l}", flush=True)
        result["trace_p50_us"] = trace_points(lines)
    return result


TRACE_LINE = re.compile(r"agp bridge trace \((\w+) side, (\w+)\), (\S+) since published: (.*)")
TRACE_POINT = re.compile(r"(\w+) p50 ([\d.]+) us")
# The points of a hop in its order, per traced topic: the sending end's, then the far end's.
TRACED = {"agp/estimates": "estimate", "agp/motor_commands": "command"}
POINTS = ["woke", "put", "arrived", "republished"]


def trace_points(lines: list[str]) -> dict:
    """`{"estimate woke": p50 us, ...}` from the bridges' trace lines of one run: how long after
    its publisher stamped it an estimate or a command reached each point of its hop."""
    got = {}
    for l in lines:
        m = TRACE_LINE.search(l)
        if not m or m.group(3) not in TRACED:
            continue
        for name, p50 in TRACE_POINT.findall(m.group(4)):
            got[f"{TRACED[m.group(3)]} {name}"] = float(p50)
    return got


def trace_line(r: list[dict]) -> str:
    """The medians over runs `r` of each trace point's p50, estimate then command."""
    parts = []
    for what in TRACED.values():
        vals = []
        for p in POINTS:
            xs = [x["trace"][f"{what} {p}"] for x in r if f"{what} {p}" in x["trace"]]
            vals.append(f"{statistics.median(xs):.1f}" if xs else "-")
        parts.append(f"{what} {', '.join(vals)}")
    return "trace p50 us since published (woke, put, arrived, republished): " + "; ".join(parts)


def figures(j: dict) -> dict:
    hops = {h["name"]: h["p50_ns"] / 1e3 for h in j["hops"]}
    link = j.get("link_floor") or {}
    return {
        "load": (j.get("load_average") or [float("nan")])[0],
        "steps_per_s": j.get("steps_per_s") or 0.0,
        "iox_floor": j["floor"]["p50_ns"] / 1e3,
        "link_floor": link.get("p50_ns", float("nan")) / 1e3,
        **{h: hops.get(h, float("nan")) for h in ["physics->estimator", *BRIDGED]},
        **{f"{h} ratio": (link.get("hops_ratio_to_link_floor_p50") or {}).get(h) or float("nan") for h in BRIDGED},
        "trace": j.get("trace_p50_us") or {},
    }


def line(tag: str, f: dict) -> str:
    return (
        f"{tag:<4} load {f['load']:5.2f}  {f['steps_per_s']:7.0f} steps/s  "
        f"link floor {f['link_floor']:6.1f} us  "
        + "  ".join(f"{h} {f[h]:6.1f} us ({f[h + ' ratio']:.2f}x)" for h in BRIDGED)
        + f"  | local physics->estimator {f['physics->estimator']:.1f} us, iceoryx2 floor {f['iox_floor']:.2f} us"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--bin", default=str(ROOT / "target/release"))
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=5.0)
    ap.add_argument("--floor-seconds", type=float, default=2.0)
    ap.add_argument("--settle", type=float, default=2.0, help="seconds between the goal and the profile")
    ap.add_argument("--ag", default=str(ROOT / "results/triangle.ag"))
    ap.add_argument("--out", default=str(ROOT / "results/bridge-profile"))
    ap.add_argument("--only", choices=["tls", "tcp"], help="one transport only")
    ap.add_argument("--against", metavar="DIR",
                    help="the binaries of another build (a copy of its agp, agp-physics, agp-estimator, agp-planner): "
                         "each run of --bin is preceded by the same run of these, so both meet the same conditions, "
                         "and the medians of both are printed")
    ap.add_argument("--trace", action="store_true",
                    help="set AGP_BRIDGE_TRACE for both bridges and print where their hops' time went (over the whole run, "
                         "the placement and the floors' pause included), after each run")
    ap.add_argument("--vary-env", metavar="K=V",
                    help="run every build a second time in each round with K=V set for every agp process, "
                         "interleaved (e.g. AGP_WAIT=block: the pipeline blocking against its default waiting)")
    ap.add_argument("--env", action="append", default=[], metavar="K=V",
                    help="set for every agp process (both supervisors, so every pipeline process and bridge, and the profiler), e.g. AGP_WAIT=block")
    args = ap.parse_args()
    for kv in args.env:
        k, _, v = kv.partition("=")
        ENV[k] = v
    if args.trace:
        ENV["AGP_BRIDGE_TRACE"] = "1"
    bin_dir, out, ag = Path(args.bin).resolve(), Path(args.out).resolve(), Path(args.ag).resolve()
    if not ag.exists():
        sys.exit(f"bench_bridge_profile: no {ag}: run `agp up` once first (it learns the triangle)")
    out.mkdir(parents=True, exist_ok=True)
    keys = out / "keys"
    if not keys.exists():
        agp(bin_dir, "bridge", "keygen", str(keys))
    transports = [t for t in ["tls", "tcp"] if args.only in (None, t)]
    # Each entry: (label, binaries, extra environment); all of them run once per round and
    # transport, one after the other, so they meet the same conditions.
    builds = [("", bin_dir, {})]
    if args.against:
        builds.insert(0, ("against ", Path(args.against).resolve(), {}))
    if args.vary_env:
        k, _, v = args.vary_env.partition("=")
        builds += [(f"{k}={v} " + b, bins, {k: v}) for b, bins, _ in list(builds)]
    runs: dict[tuple[str, str], list[dict]] = {(b, t): [] for b, _, _ in builds for t in transports}
    base_env = dict(ENV)
    for k in range(args.rounds):
        for tag in transports:
            for build, bins, extra in builds:
                ENV.clear()
                ENV.update(base_env, **extra)
                f = figures(one_run(bins, out, ag, keys, tag == "tls", k, args))
                runs[(build, tag)].append(f)
                print(build + line(tag, f), flush=True)
    print(f"\nmedians over {args.rounds} rounds ({args.seconds} s sampled, {args.floor_seconds} s per floor){' with ' + ' '.join(args.env) if args.env else ''}:")
    for build, bins, _ in builds:
        for tag in transports:
            r = runs[(build, tag)]
            med = {key: statistics.median(x[key] for x in r) for key in r[0] if key != "trace"}
            print(build + line(tag, med) + f"  [load {min(x['load'] for x in r):.1f}-{max(x['load'] for x in r):.1f}] ({bins})")
            print(f"{build}{tag:<4} rounds: " + "  ".join(
                f"{h} " + " / ".join(f"{x[h + ' ratio']:.2f}x" for x in r) for h in BRIDGED))
            if args.trace:
                print(f"{build}{tag:<4} {trace_line(r)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
