#!/usr/bin/env python3
"""Decodes every Foxglove channel of an agp recording with the stock decoders from PyPI: the
`mcap` reader and `mcap-protobuf-support`'s DecoderFactory (protobuf messages built from the
FileDescriptorSet each channel's schema carries), as any tool without agp would.

    .venv-ci/bin/python tools/foxglove_decode.py run.mcap [--json out.json]

Prints per channel its topic, schema, message count and one decoded field as a sample; the
raw `agp-repr-c` channels are counted, not decoded (no stock decoder knows them). Exit
status 1 when a protobuf message fails to decode or when no protobuf channel is found.
"""

import argparse
import json
import sys

try:
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory
except ModuleNotFoundError as e:
    sys.exit(
        f"foxglove_decode: the package `{e.name}` is not installed: run tools/setup.sh and use "
        ".venv-ci/bin/python tools/foxglove_decode.py"
    )


def sample(schema_name, msg):
    """A few words of a decoded message, to show that it decoded into something."""
    if schema_name == "foxglove.SceneUpdate":
        return "entities " + ",".join(e.id for e in msg.entities)
    if schema_name == "foxglove.FrameTransforms":
        return "frames " + ",".join(t.child_frame_id for t in msg.transforms)
    if schema_name == "foxglove.PoseInFrame":
        p = msg.pose.position
        return f"({p.x * 1e3:.1f}, {p.y * 1e3:.1f}) mm in {msg.frame_id}"
    if schema_name == "foxglove.PointCloud":
        return f"{len(msg.data) // max(msg.point_stride, 1)} points"
    if schema_name == "foxglove.Grid":
        return f"{msg.column_count} columns, {len(msg.data)} bytes in {msg.frame_id}"
    if schema_name == "foxglove.RawImage":
        return f"{msg.width}x{msg.height} {msg.encoding}"
    if schema_name == "foxglove.Log":
        return f"{msg.name}: {msg.message}"
    return type(msg).__name__


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("file")
    ap.add_argument("--json", help="write the counts as JSON to this file")
    args = ap.parse_args()

    counts = {}  # topic -> {schema, encoding, messages, decoded, errors, sample}
    factory = DecoderFactory()
    decoders = {}
    with open(args.file, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages():
            c = counts.setdefault(
                channel.topic,
                {
                    "schema": schema.name if schema else "",
                    "encoding": channel.message_encoding,
                    "messages": 0,
                    "decoded": 0,
                    "errors": 0,
                    "first_error": None,
                    "sample": None,
                },
            )
            c["messages"] += 1
            if channel.message_encoding != "protobuf":
                continue
            if channel.id not in decoders:
                decoders[channel.id] = factory.decoder_for(channel.message_encoding, schema)
            decode = decoders[channel.id]
            try:
                msg = decode(message.data)
            except Exception as e:  # any failure of the stock decoder counts
                c["errors"] += 1
                c["first_error"] = c["first_error"] or str(e)
                continue
            c["decoded"] += 1
            if c["sample"] is None or c["messages"] % 50 == 0:
                c["sample"] = sample(c["schema"], msg)

    print(f"{'topic':<20} {'schema':<26} {'encoding':<11} {'messages':>9} {'decoded':>8} {'errors':>7}  sample")
    for topic, c in sorted(counts.items()):
        print(
            f"{topic:<20} {c['schema']:<26} {c['encoding']:<11} {c['messages']:>9} "
            f"{c['decoded'] if c['encoding'] == 'protobuf' else '-':>8} {c['errors']:>7}  {c['sample'] or ''}"
        )
    protobuf = [c for c in counts.values() if c["encoding"] == "protobuf"]
    errors = sum(c["errors"] for c in protobuf)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(counts, f, indent=1)
    if not protobuf:
        print("foxglove_decode: no protobuf channel in the recording", file=sys.stderr)
        return 1
    if errors:
        print(f"foxglove_decode: {errors} message(s) failed to decode", file=sys.stderr)
        return 1
    print(
        f"foxglove_decode: {len(protobuf)} protobuf channels, "
        f"{sum(c['decoded'] for c in protobuf)} messages decoded, none failed"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
