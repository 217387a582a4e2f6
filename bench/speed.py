"""Speed of a simulated team: simulated time over wall time at 10 Hz control.

Runs `btrack sim` (world, recorder and N agents as separate processes) for each team
size, --repeat times, and prints the world's tick rate and speed-up (median, min and
max over the repeats: a shared 2-core machine varies by +-20 % run to run) and the
whole command's wall time, start-up and the recorder's catch-up included.

``--bare`` adds, before each setting, the same world and agents with nothing else: no
recorder, no launcher, a plain ``btrack router`` only for discovery. It measures what
the machine gives the lockstep at that moment (this shared host's speed drifts by a
third within an hour), so a change can be told from the host's drift. Usage:

    .venv/bin/python bench/speed.py [--robots 3 10] [--duration 600] [--repeat 5] [--bare]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, nargs="+", default=[3])
    p.add_argument("--duration", type=float, default=600.0)
    p.add_argument("--map", default="half-algae")
    p.add_argument("--repeat", type=int, default=3, help="runs per setting (3)")
    p.add_argument("--localization", nargs="+", default=["truth", "pf"],
                   help="pose sources to measure (default: truth pf)")
    p.add_argument("--bare", action="store_true",
                   help="also time world + agents alone (no recorder): the host's state")
    args = p.parse_args()
    print(f"{'poses':>8} {'robots':>6} {'sim s':>7} {'world s':>8} {'ticks/s':>8} "
          f"{'speed-up median (min-max)':>27} {'command s':>10}")
    for loc in args.localization:
        run_team_sizes(args, loc)
    return 0


def bare_speedup(n: int, duration: float, loc: str) -> float:
    """World and n agents alone, peers of a plain router used for discovery only."""
    from deploy.procs import ProcessGroup, free_port, wait_listening

    port = free_port()
    hub = f"tcp/127.0.0.1:{port}"
    ns = f"bench/bare-{port}"
    peer = ["--ns", ns, "--mode", "peer", "--connect", hub, "--listen", "tcp/127.0.0.1:0",
            "--no-multicast"]
    with tempfile.TemporaryDirectory() as tmp:
        group = ProcessGroup(Path(tmp))
        try:
            router = group.start("router", ["router", "--listen", hub, "--ns", ns,
                                            "--no-multicast"])
            if not wait_listening(port, router, 30.0):
                raise SystemExit(f"bench: the router did not listen on {hub}")
            for i in range(n):
                group.start(f"agent{i}", ["agent", "--id", str(i), "--robots", str(n), *peer])
            world = group.start("world", ["world", "--robots", str(n), "--localization", loc,
                                          "--duration", str(duration), *peer])
            if world.proc.wait() != 0:
                raise SystemExit(f"bench: the bare world failed:\n{world.log_tail()}")
            log = world.stdout_path.read_text().strip().splitlines()[-1]
            return float(json.loads(log)["speedup"])
        finally:
            group.stop_all()


def sim_command(n: int, duration: float, gmap: str, loc: str, out: Path) -> list[str]:
    """The ``btrack sim`` command line of a timed run: no progress, report or scene."""
    return [sys.executable, "-m", "btrack", "sim", "--robots", str(n), "--map", gmap,
            "--localization", loc, "--duration", str(duration), "--out", str(out),
            "--quiet", "--no-report", "--no-scene"]


def world_summary(out: Path) -> dict[str, Any]:
    """The world's closing line of a finished run in ``out``: ticks, wall_s, speedup."""
    log = (out / "logs" / "world.out").read_text().strip().splitlines()[-1]
    summary: dict[str, Any] = json.loads(log)
    return summary


def team_run(n: int, duration: float, gmap: str, loc: str, extra: Sequence[str] = ()
             ) -> tuple[dict[str, Any], float]:
    """One ``btrack sim`` run (``extra``: more of its options): the world's closing line
    and the whole command's wall s."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "run"
        began = time.monotonic()
        subprocess.run([*sim_command(n, duration, gmap, loc, out), *extra], check=True,
                       stdout=subprocess.DEVNULL)
        return world_summary(out), time.monotonic() - began


def run_team_sizes(args: argparse.Namespace, loc: str) -> None:
    for n in args.robots:
        if args.bare and loc != "pf":
            bare = [bare_speedup(n, args.duration, loc) for _ in range(args.repeat)]
            print(f"{'bare':>8} {n:>6} {args.duration:>7.0f} {'':>8} {'':>8} "
                  f"{statistics.median(bare):>12.1f}x ({min(bare):.1f}-{max(bare):.1f}x)",
                  flush=True)
        worlds, commands = [], []
        for _ in range(args.repeat):
            world, command_s = team_run(n, args.duration, args.map, loc)
            worlds.append(world)
            commands.append(command_s)
        speeds = [w["speedup"] for w in worlds]
        walls = [w["wall_s"] for w in worlds]
        wall = statistics.median(walls)
        ticks = statistics.median(w["ticks"] for w in worlds)
        print(f"{loc:>8} {n:>6} {args.duration:>7.0f} {wall:>8.2f} {ticks / wall:>8.0f} "
              f"{statistics.median(speeds):>12.1f}x ({min(speeds):.1f}-{max(speeds):.1f}x) "
              f"{statistics.median(commands):>10.1f}", flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
