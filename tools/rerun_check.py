#!/usr/bin/env python3
"""An agp recording in Rerun, from the pinned `rerun-sdk` (tools/requirements-ci.txt), offline.

    .venv-ci/bin/python tools/rerun_check.py entities run.mcap [--rrd run.rrd] [--json out.json]
    .venv-ci/bin/python tools/rerun_check.py browser run.mcap --png shot.png [--keep DIR]

`entities`: Rerun's own MCAP reader (what `rerun run.mcap` and `rerun mcap convert` use)
loads the file; prints each entity it made and its components (Rerun converts Foxglove's
PointCloud, PoseInFrame, FrameTransforms, Grid-less), and writes the .rrd. Exit 1 when the
robot, the object or the IR did not become an entity with points.

`browser`: the recording's last scene as an .rrd, with a blueprint whose 3D view
looks straight down (+x right, +y up) at the object's last estimated position; Rerun's web
viewer (`rerun --web-viewer`, served from the wheel, no network) on it, opened in Debian's
headless Chromium by tools/foxglove-client/screenshot.cjs (puppeteer-core); then the PNG is
read back (a small PNG reader below, no package) and checked: the object's green
(agp_view's OBJECT_RGBA) is in the picture, near the view's centre where the camera looks,
and its centroid lies where the recording puts the object relative to the robot's blue
disc (whose width gives the picture's scale), within 10 px + 15 % of their distance.
Exit 1 when not.
"""

import argparse
import json
import math
import os
import socket
import struct
import subprocess
import sys
import tempfile
import time
import zlib

try:
    import numpy as np
    import pyarrow as pa
    import rerun as rr
    import rerun.blueprint as rrb
except ModuleNotFoundError as e:
    sys.exit(
        f"rerun_check: the package `{e.name}` is not installed: run tools/setup.sh and use "
        ".venv-ci/bin/python tools/rerun_check.py"
    )

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
APP_ID = "agp"
# agp_view::scene's colours of the point clouds.
OBJECT_RGB = (51, 230, 102)
ROBOT_RGB = (77, 128, 217)
POINT_ENTITIES = ["/robot/points", "/estimate/points", "/ir/points"]
# The E-puck's body radius (agp_world::RobotDescription::epuck().body_radius), m.
ROBOT_BODY_RADIUS_M = 0.037


def reader(path, start_time_ns=None):
    return rr.chunk.McapReader(path, start_time_ns=start_time_ns)


def entities_of(path):
    """Entity path -> sorted component columns, and the last positions of each point cloud."""
    found = {}
    last_points = {}
    last_time = {}
    for chunk in reader(path).stream():
        batch = chunk.to_record_batch()
        cols = found.setdefault(chunk.entity_path, set())
        for name in batch.schema.names:
            if ":" in name and not name.startswith(("rerun.controls", "Mcap")):
                cols.add(name)
        if chunk.entity_path in POINT_ENTITIES and "Points3D:positions" in batch.schema.names:
            times = [n for n in batch.schema.names if n in ("message_log_time", "log_time", "timestamp")]
            col = batch.column("Points3D:positions").to_pylist()
            if times:
                t = batch.column(times[0]).cast(pa.int64()).to_pylist()
            else:
                t = list(range(len(col)))
            for when, pos in zip(t, col):
                if pos and (chunk.entity_path not in last_time or when >= last_time[chunk.entity_path]):
                    last_time[chunk.entity_path] = when
                    last_points[chunk.entity_path] = pos
    return {k: sorted(v) for k, v in sorted(found.items())}, last_points, last_time


def cmd_entities(args):
    entities, last, _ = entities_of(args.file)
    print(f"Rerun {rr.__version__}: {len(entities)} entities from {args.file}")
    for path, cols in entities.items():
        print(f"  {path:<22} {', '.join(cols)}")
    if args.rrd:
        reader(args.file).stream().write_rrd(args.rrd, application_id=APP_ID, recording_id="agp-recording")
        print(f"rerun_check: wrote {args.rrd}")
    summary = {"rerun": rr.__version__, "entities": entities,
               "last_points": {k: len(v) for k, v in last.items()}}
    if args.json:
        with open(args.json, "w") as f:
            json.dump(summary, f, indent=1)
    missing = [p for p in POINT_ENTITIES if "Points3D:positions" not in entities.get(p, [])]
    if missing:
        print(f"rerun_check: no points for {missing}", file=sys.stderr)
        return 1
    return 0


# --- a PNG reader: 8-bit RGB/RGBA, not interlaced (what Chromium writes) -----------------------

def read_png(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG")
    at, idat = 8, b""
    width = height = depth = ctype = interlace = None
    while at < len(data):
        (n,) = struct.unpack(">I", data[at:at + 4])
        kind = data[at + 4:at + 8]
        body = data[at + 8:at + 8 + n]
        at += 12 + n
        if kind == b"IHDR":
            width, height, depth, ctype, _, _, interlace = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            break
    if depth != 8 or ctype not in (2, 6) or interlace != 0:
        raise ValueError(f"unsupported PNG: depth {depth}, colour type {ctype}, interlace {interlace}")
    bpp = 3 if ctype == 2 else 4
    raw = zlib.decompress(idat)
    stride = width * bpp
    out = np.zeros((height, stride), dtype=np.uint8)
    prev = np.zeros(stride, dtype=np.int32)
    pos = 0
    for y in range(height):
        ftype = raw[pos]
        line = np.frombuffer(raw, dtype=np.uint8, count=stride, offset=pos + 1).astype(np.int32)
        pos += 1 + stride
        if ftype == 0:
            cur = line
        elif ftype == 1:
            cur = line.copy()
            for x in range(bpp, stride):
                cur[x] = (cur[x] + cur[x - bpp]) & 255
        elif ftype == 2:
            cur = (line + prev) & 255
        elif ftype == 3:
            cur = line.copy()
            for x in range(stride):
                left = cur[x - bpp] if x >= bpp else 0
                cur[x] = (cur[x] + ((left + prev[x]) >> 1)) & 255
        elif ftype == 4:
            cur = line.copy()
            for x in range(stride):
                a = cur[x - bpp] if x >= bpp else 0
                b = prev[x]
                c = prev[x - bpp] if x >= bpp else 0
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if (pa <= pb and pa <= pc) else (b if pb <= pc else c)
                cur[x] = (cur[x] + pred) & 255
        else:
            raise ValueError(f"bad PNG filter {ftype}")
        out[y] = cur
        prev = cur
    return out.reshape(height, width, bpp)[:, :, :3]


def mask_of(img, rgb, tol=40):
    d = np.abs(img.astype(np.int32) - np.array(rgb, dtype=np.int32)).sum(axis=2)
    return d <= tol


def free_port():
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def cmd_browser(args):
    work = args.keep or tempfile.mkdtemp(prefix="agp-rerun-")
    os.makedirs(work, exist_ok=True)
    # The last scene only (every scene channel is written at one log time): whatever time
    # the viewer shows once it has loaded, it shows the recording's end.
    _, last, last_time = entities_of(args.file)
    start = min(last_time[p] for p in POINT_ENTITIES)
    rrd = os.path.join(work, "end.rrd")
    reader(args.file, start_time_ns=start).stream().write_rrd(rrd, application_id=APP_ID, recording_id="agp-end")
    obj = np.array(last["/estimate/points"], dtype=float)[:, :2]
    robot = np.array(last["/robot/points"], dtype=float)[:, :2]
    oc, rc = obj.mean(axis=0), robot.mean(axis=0)
    print(f"rerun_check: the recording ends with the object estimated at ({oc[0]*1e3:.1f}, {oc[1]*1e3:.1f}) mm "
          f"and the robot at ({rc[0]*1e3:.1f}, {rc[1]*1e3:.1f}) mm")
    height = 0.45
    view = rrb.Spatial3DView(
        origin="/",
        name="agp",
        eye_controls=rrb.EyeControls3D(
            kind=rrb.Eye3DKind.Orbital,
            position=[float(oc[0]), float(oc[1]), height],
            look_target=[float(oc[0]), float(oc[1]), 0.0],
            eye_up=[0.0, 1.0, 0.0],
        ),
        background=rrb.Background(color=[255, 255, 255]),
    )
    rbl = os.path.join(work, "top-down.rbl")
    rrb.Blueprint(view, collapse_panels=True).save(APP_ID, rbl)
    web_port, grpc_port = free_port(), free_port()
    log = open(os.path.join(work, "rerun.log"), "w")
    server = subprocess.Popen(
        [os.path.join(REPO, ".venv-ci/bin/rerun"), "--web-viewer", "--bind", "127.0.0.1",
         "--web-viewer-port", str(web_port), "--port", str(grpc_port), "--renderer", "webgl",
         rrd, rbl],
        stdout=log, stderr=subprocess.STDOUT, env={**os.environ, "RERUN_ANALYTICS": "off", "BROWSER": "true"},
        start_new_session=True,
    )
    try:
        url = None
        deadline = time.time() + 60
        while time.time() < deadline and url is None:
            time.sleep(0.5)
            if server.poll() is not None:
                break
            with open(log.name) as f:
                for line in f:
                    for word in line.split():
                        if word.startswith("http://") and str(web_port) in word:
                            url = word.strip(".,'\"")
        if url is None:
            with open(log.name) as f:
                print(f.read(), file=sys.stderr)
            print("rerun_check: the web viewer did not say where it serves", file=sys.stderr)
            return 1
        print(f"rerun_check: Rerun's web viewer at {url}")
        shot = subprocess.run(
            ["node", os.path.join(REPO, "tools/foxglove-client/screenshot.cjs"), "--url", url,
             "--out", args.png, "--wait-s", str(args.wait_s)],
            capture_output=True, text=True, timeout=240,
        )
        print(shot.stdout, end="")
        if shot.returncode != 0:
            print(shot.stderr, file=sys.stderr)
            return 1
    finally:
        os.killpg(server.pid, 15)
        server.wait(timeout=20)
    img = read_png(args.png)
    h, w, _ = img.shape
    green, blue = mask_of(img, OBJECT_RGB), mask_of(img, ROBOT_RGB)
    result = {"png": args.png, "size": [w, h], "green_pixels": int(green.sum()), "blue_pixels": int(blue.sum())}
    ok = True
    if green.sum() < 50:
        ok = False
        result["why"] = "the object's green is not in the picture"
    else:
        gy, gx = np.nonzero(green)
        g = np.array([gx.mean(), gy.mean()])
        result["green_centroid_px"] = g.round(1).tolist()
        # The camera looks straight down at the object's last estimated position; Rerun
        # does not always centre it exactly (seen 0.14 of the height off), so the region
        # is checked against the robot drawn beside it: the robot's blue disc gives the
        # scale (its width is the body's diameter), and the object's green must lie where
        # the recording puts it relative to the robot.
        centre = np.array([w / 2, h / 2])
        off = np.abs(g - centre) / np.array([w, h])
        result["green_off_centre"] = off.round(3).tolist()
        if (off > 0.3).any():
            ok = False
            result["why"] = "the object's green is not round the view's centre, where the camera looks"
        if blue.sum() < 50:
            ok = False
            result["why"] = "the robot's blue is not in the picture"
        else:
            by, bx = np.nonzero(blue)
            b = np.array([bx.mean(), by.mean()])
            result["blue_centroid_px"] = b.round(1).tolist()
            px_per_m = (bx.max() - bx.min()) / (2 * ROBOT_BODY_RADIUS_M)
            # +x right, +y up: the image's rows grow downwards.
            expected = b + px_per_m * np.array([oc[0] - rc[0], -(oc[1] - rc[1])])
            err = float(np.linalg.norm(g - expected))
            dist = float(np.linalg.norm(expected - b))
            result["px_per_m"] = round(float(px_per_m), 1)
            result["green_expected_px"] = expected.round(1).tolist()
            result["green_error_px"] = round(err, 1)
            if err > 10 + 0.15 * dist:
                ok = False
                result["why"] = "the object's green is not where the recording puts it beside the robot"
    print(json.dumps(result))
    if not ok:
        print(f"rerun_check: {result['why']}", file=sys.stderr)
        return 1
    print("rerun_check: the object is in the screenshot where the recording puts it")
    return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    e = sub.add_parser("entities")
    e.add_argument("file")
    e.add_argument("--rrd")
    e.add_argument("--json")
    b = sub.add_parser("browser")
    b.add_argument("file")
    b.add_argument("--png", required=True)
    b.add_argument("--keep", help="keep the .rrd, blueprint and server log in this folder")
    b.add_argument("--wait-s", type=float, default=30.0)
    args = ap.parse_args()
    return cmd_entities(args) if args.cmd == "entities" else cmd_browser(args)


if __name__ == "__main__":
    sys.exit(main())
