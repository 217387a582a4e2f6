"""Benchmark: the localizer core's time per scan (blobs, centres, assignment, and every
robot's particle filter: prediction, update, resampling when due), on simulated LMS
scans of robots driving in front of the scanner. Goals (BENCHMARKS.md): 3 robots x
1,000 particles under 2 ms, 30 robots x 1,000 particles under 20 ms.

    .venv/bin/python bench/localizer.py --robots 3 30 --particles 1000 --scans 600
"""

from __future__ import annotations

import argparse
import math
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from localizer.core import FilterConfig, Localizer, ScanGeometry  # noqa: E402
from simworld.laser import Laser, Scanner  # noqa: E402


def layout(n: int) -> np.ndarray:
    """Start positions: a grid over 0..6 m along the edge and -1.5..2 m across it,
    at least 0.5 m apart (30 robots: 6 x 5)."""
    cols = min(n, 6)
    rows = math.ceil(n / cols)
    xs = np.linspace(0.3, 5.7, cols)
    ys = np.linspace(-1.2, 1.8, rows) if rows > 1 else np.array([-1.0])
    grid = np.array([(x, y) for y in ys for x in xs])[:n]
    return grid


def bench(robots: int, particles: int, scans: int, seed: int = 1) -> dict[str, float]:
    scanner = Scanner(3.0, -2.0)
    laser = Laser(scanner, seed=seed)
    geometry = ScanGeometry(scanner.x, scanner.y, scanner.theta, scanner.angle_min,
                            scanner.angle_step, scanner.range_max, scanner.beams)
    start = layout(robots)
    rng = np.random.default_rng(seed)
    heading = rng.uniform(-math.pi, math.pi, robots)
    speed, turn, dt = 0.3, 0.4, 0.1  # m/s and rad/s: every robot drives a slow circle
    pos = start.copy()
    scans_in, odom = [], []
    for k in range(scans):
        scans_in.append(np.asarray(laser.scan(pos)))
        d = np.full(robots, speed * dt if k else 0.0)
        w = np.full(robots, turn * dt if k else 0.0)
        odom.append((d, w))
        mid = heading + 0.5 * turn * dt
        pos = pos + speed * dt * np.stack([np.cos(mid), np.sin(mid)], axis=1)
        heading = heading + turn * dt
    loc = Localizer(robots, FilterConfig(particles=particles), seed=seed)
    times = np.empty(scans)
    cpu = np.empty(scans)
    for k in range(scans):
        began, began_cpu = time.perf_counter(), time.process_time()
        loc.step(scans_in[k], geometry, odom[k][0], odom[k][1])
        times[k] = time.perf_counter() - began
        cpu[k] = time.process_time() - began_cpu
    steady = times[10:] * 1000.0  # the first scans seed the filters
    return {
        "cpu_mean_ms": float(cpu[10:].mean() * 1000.0),
        "robots": robots,
        "particles": particles,
        "mean_ms": float(steady.mean()),
        "median_ms": float(np.median(steady)),
        "p95_ms": float(np.percentile(steady, 95)),
        "resampled_per_scan": loc.resampled / scans,
    }


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, nargs="+", default=[3, 30])
    p.add_argument("--particles", type=int, default=1000)
    p.add_argument("--scans", type=int, default=600)
    args = p.parse_args()
    print(f"# {platform.python_version()}, numpy {np.__version__}, {args.scans} scans each")
    print("| robots | particles | mean ms | median ms | p95 ms | CPU mean ms "
          "| resampled robots/scan |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for n in args.robots:
        r = bench(n, args.particles, args.scans)
        print(f"| {n} | {args.particles} | {r['mean_ms']:.2f} | {r['median_ms']:.2f} | "
              f"{r['p95_ms']:.2f} | {r['cpu_mean_ms']:.2f} | {r['resampled_per_scan']:.2f} |",
              flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
