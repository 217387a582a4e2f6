"""Speed of a simulated team: simulated time over wall time at 10 Hz control.

Runs `btrack sim` (world, recorder and N agents as separate processes) for each team
size and prints the world's own tick rate and the speed-up. Usage:

    .venv/bin/python bench/speed.py [--robots 3 10] [--duration 600]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, nargs="+", default=[3])
    p.add_argument("--duration", type=float, default=600.0)
    p.add_argument("--map", default="half-algae")
    p.add_argument("--localization", nargs="+", default=["truth", "pf"],
                   help="pose sources to measure (default: truth pf)")
    args = p.parse_args()
    print(f"{'poses':>8} {'robots':>6} {'sim s':>7} {'wall s':>7} {'ticks/s':>8} {'speed-up':>9}")
    for loc in args.localization:
        run_team_sizes(args, loc)
    return 0


def run_team_sizes(args: argparse.Namespace, loc: str) -> None:
    for n in args.robots:
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "run"
            subprocess.run(
                [sys.executable, "-m", "btrack", "sim", "--robots", str(n), "--map", args.map,
                 "--localization", loc, "--duration", str(args.duration), "--out", str(out),
                 "--quiet", "--no-report"],
                check=True, stdout=subprocess.DEVNULL,
            )
            world = json.loads((out / "logs" / "world.out").read_text().strip().splitlines()[-1])
            print(f"{loc:>8} {n:>6} {args.duration:>7.0f} {world['wall_s']:>7.2f} "
                  f"{world['ticks'] / world['wall_s']:>8.0f} {world['speedup']:>8.1f}x",
                  flush=True)


if __name__ == "__main__":
    raise SystemExit(main())
