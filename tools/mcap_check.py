#!/usr/bin/env python3
"""Reads an agp recording with the stock `mcap` package from PyPI and sets its counts beside
what `agp status --json` reported while it was recorded.

    python3 -m venv /tmp/mcapvenv && /tmp/mcapvenv/bin/pip install mcap
    agp status --instance live --json > status.json       # while `agp record` runs
    /tmp/mcapvenv/bin/python tools/mcap_check.py live.mcap --status status.json

For each channel: its topic (the iceoryx2 service), schema (the payload's iceoryx2 type
name), encodings and message count; the span of log times; the recorder's own account
(received, dropped, lost; the `agp.recording` metadata). With `--status`, the IR frames and
motor commands are set beside the rates `agp status` gave physics and the driving planner
(messages per second over its last second, several files averaged): expected = rate x the
recording's span. Exit status 1 when a count is more than `--tolerance` (1 %) off, or when a
channel of the recorded topics is missing.
"""

import argparse
import json
import struct
import sys

try:
    from mcap.reader import make_reader
except ModuleNotFoundError:
    sys.exit(
        "mcap_check: the `mcap` package is not installed: run tools/setup.sh and use "
        ".venv-ci/bin/python tools/mcap_check.py (or: pip install mcap==1.6.0)"
    )

TOPICS = [
    "agp/ir_frames",
    "agp/motor_commands",
    "agp/resets",
    "agp/estimates",
    "agp/grids",
    "agp/task",
    "agp/goal",
    "agp/active_epoch",
    "agp/learn_events",
    "agp/learn_reports",
    "agp/goal_ends",
]

# (status process, status rate topic) -> recorded channel
RATES = {"physics": "agp/ir_frames", "planner": "agp/motor_commands"}


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mcap")
    ap.add_argument("--status", nargs="*", default=[], help="`agp status --json` outputs")
    ap.add_argument("--tolerance", type=float, default=0.01)
    args = ap.parse_args()

    counts, first, last, sizes, steps = {}, {}, {}, {}, []
    with open(args.mcap, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        channels = {c.id: c for c in summary.channels.values()}
        schemas = summary.schemas
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            t = channel.topic
            counts[t] = counts.get(t, 0) + 1
            first[t] = min(first.get(t, message.log_time), message.log_time)
            last[t] = max(last.get(t, message.log_time), message.log_time)
            sizes[t] = len(message.data)
            if t == "agp/ir_frames":
                # IrFrame.v2: `step` is the u64 at offset 144 (see the schema text).
                steps.append(struct.unpack_from("<Q", message.data, 144)[0])

    ok = True
    run = metadata.get("agp.run", {})
    print(f"file {args.mcap}: agp {run.get('agp_version', '?')}, instance `{run.get('instance', '?')}`, "
          f"scenario {run.get('scenario', '?')}, clock {run.get('clock', '?')}, seed {run.get('seed', '?')}")
    span_ns = max(last.values(), default=0) - min(first.values(), default=0)
    span = span_ns * 1e-9
    print(f"log times span {span:.3f} s; {len(channels)} channels")
    rec = metadata.get("agp.recording", {})
    print(f"{'topic':<20} {'schema':<24} {'encoding':<11} {'bytes':>6} {'messages':>9} {'per s':>8} {'dropped':>8} {'lost':>6}")
    by_topic = {c.topic: c for c in channels.values()}
    for topic in TOPICS:
        c = by_topic.get(topic)
        if c is None:
            print(f"{topic:<20} MISSING")
            ok = False
            continue
        s = schemas[c.schema_id]
        n = counts.get(topic, 0)
        print(f"{topic:<20} {s.name:<24} {c.message_encoding:<11} {sizes.get(topic, 0):>6} {n:>9} "
              f"{n / span if span else 0:>8.1f} {rec.get(topic + '.dropped', '?'):>8} {rec.get(topic + '.lost', '?'):>6}")
    foxglove = sorted((c.topic, schemas[c.schema_id].name) for c in channels.values()
                      if c.message_encoding == "protobuf" and c.schema_id in schemas)
    if foxglove:
        print(f"{len(foxglove)} Foxglove channels (protobuf; decode them with tools/foxglove_decode.py): "
              + ", ".join(f"{t} {n} ({counts.get(t, 0)})" for t, n in foxglove))
    if steps:
        gaps = sum(max(0, b - a - 1) for a, b in zip(steps, steps[1:]))
        print(f"IR frames: steps {steps[0]} .. {steps[-1]} ({steps[-1] - steps[0] + 1} steps), {gaps} missing in between")

    if args.status:
        rates = {}
        for path in args.status:
            with open(path) as f:
                st = json.load(f)
            for p in st.get("processes", []):
                if p.get("name") in RATES and p.get("rate_per_s"):
                    rates.setdefault(p["name"], []).append(p["rate_per_s"])
        for name, topic in RATES.items():
            if name not in rates:
                print(f"{topic}: no rate of `{name}` in the status files")
                continue
            rate = sum(rates[name]) / len(rates[name])
            # The channel's own span (first to last message) holds n - 1 intervals.
            own = (last[topic] - first[topic]) * 1e-9 if topic in last else 0
            expected = rate * own + 1
            n = counts.get(topic, 0)
            off = (n - expected) / expected if expected else float("inf")
            within = abs(off) <= args.tolerance
            ok &= within
            print(f"{topic}: {n} recorded over {own:.3f} s; `agp status` gave `{name}` {rate:.1f}/s "
                  f"(mean of {len(rates[name])}) -> {expected:.0f} expected; {off * 100:+.2f} % "
                  f"({'within' if within else 'NOT within'} {args.tolerance * 100:.0f} %)")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
