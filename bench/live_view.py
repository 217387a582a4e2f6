"""The lockstep's speed with and without a Foxglove viewer watching (issue 20: within
10 %). Alternates runs of `btrack sim` without `--live` and with `--live` and a real
Foxglove WebSocket client (tests/foxglove_client, node) subscribed to every channel for
the whole run, and prints the world's speed-up of each (simulated over the wall time
between its first and last tick) and the medians. Usage:

    .venv/bin/python bench/live_view.py [--robots 3] [--duration 300] [--repeat 3]
        [--localization pf]
"""

from __future__ import annotations

import argparse
import json
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CLIENT = Path(__file__).resolve().parent.parent / "tests" / "foxglove_client"
TOPICS = ("/scene/map,/scene/robots,/scene/segments,/scan/0,/tf,/poses/true,"
          "/poses/estimated,/plot/errors,/plot/segments")


def _listening(port: int) -> bool:
    with socket.socket() as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def one_run(args: argparse.Namespace, live: bool) -> tuple[float, int]:
    """The world's speed-up, and the messages the viewer received (0 without one)."""
    from deploy.procs import free_port

    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        port = free_port()
        cmd = [sys.executable, "-m", "btrack", "sim", "--robots", str(args.robots),
               "--localization", args.localization, "--duration", str(args.duration),
               "--out", str(out), "--quiet", "--no-report", "--no-scene"]
        sim = subprocess.Popen(cmd + (["--live", str(port)] if live else []),
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        client = None
        if live:
            while not _listening(port):
                if sim.poll() is not None:
                    raise SystemExit(f"bench: btrack sim ended first: {sim.stderr}")
                time.sleep(0.05)
            # never satisfied (10^9 messages a topic): it watches until it is ended
            client = subprocess.Popen(["node", str(CLIENT / "client.mjs"),
                                       f"ws://127.0.0.1:{port}", TOPICS, "1000000000",
                                       "100000"], stdout=subprocess.PIPE, text=True)
        if sim.wait() != 0:
            err = sim.stderr.read() if sim.stderr else ""
            raise SystemExit(f"bench: btrack sim failed: {err[-2000:]}")
        received = 0
        if client is not None:
            client.terminate()
            client.wait()
        view = out / "logs" / "view.out"
        if live and view.exists():
            received = json.loads(view.read_text().strip().splitlines()[-1])["messages"]
        world = json.loads((out / "logs" / "world.out").read_text().strip().splitlines()[-1])
        return float(world["speedup"]), received


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--duration", type=float, default=300.0)
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--localization", default="pf")
    args = p.parse_args()
    off: list[float] = []
    on: list[float] = []
    for i in range(args.repeat):
        for live in (False, True) if i % 2 == 0 else (True, False):
            speed, sent = one_run(args, live)
            (on if live else off).append(speed)
            print(f"run {i + 1}: {'with' if live else 'without'} a viewer: {speed:.1f}x"
                  + (f" ({sent} view messages served)" if live else ""), flush=True)
    a, b = statistics.median(off), statistics.median(on)
    print(f"median without {a:.1f}x ({min(off):.1f}-{max(off):.1f}), with {b:.1f}x "
          f"({min(on):.1f}-{max(on):.1f}): {100 * (b - a) / a:+.1f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
