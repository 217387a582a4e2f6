"""``btrack scene RUN``: add the Foxglove channels to a recording (``btrack sim`` does it
at a run's end), or with ``--png`` draw one tick of them from above."""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack scene",
        description="Add Foxglove's well-known channels (LaserScan, FrameTransforms, "
        "PosesInFrame, SceneUpdate, plottable errors and segments) to a finished "
        "recording, beside its raw messages; or draw one tick of them (--png).")
    p.add_argument("run", metavar="RUN", help="a run.mcap, or the run directory holding one")
    p.add_argument("--png", type=Path, metavar="FILE",
                   help="draw the scene of one tick from the Foxglove channels instead")
    p.add_argument("--at", type=float, default=None, metavar="SECONDS",
                   help="with --png: the simulated time to draw (default: the run's end)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    from scene.convert import ConvertError, add_foxglove, recording_path

    path = recording_path(args.run)
    if args.png is None:
        began = time.monotonic()
        try:
            counts = add_foxglove(path)
        except ConvertError as exc:
            print(f"btrack scene: {exc}", file=sys.stderr)
            return 2
        print(json.dumps({**counts, "seconds": round(time.monotonic() - began, 2)}))
        return 0
    from scene.render import draw, read_frame

    if not path.is_file():
        print(f"btrack scene: no recording at {path}", file=sys.stderr)
        return 2
    try:
        frame = read_frame(path, float("inf") if args.at is None else args.at)
    except Exception as exc:  # not MCAP, no view channels: say so, no traceback
        print(f"btrack scene: cannot draw {path}: {exc}", file=sys.stderr)
        return 2
    print(draw(frame, args.png))
    return 0
