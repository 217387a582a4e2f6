"""The thesis's twelve cases in one process, for choosing gains: seconds, not minutes.

The in-process engine (``deploy.engine``, which ``btrack suite general`` runs too): the
world core and one controller per robot, stepped in lockstep the way the bus runs
them. The measures are the report's (``report.measures``): the mean |error|
over neighbour pairs and the last quarter, phase by the thesis's eq. 3.1 from the true
x, workload from the boundaries and the map's true depth profile; and, as the suite
reports for odometry, the same from the phases and workloads the agents published.
The run is the one ``btrack sim`` makes with the same case, seed and pose source, bit
for bit (a test compares the tracks); only timeouts under load could make the bus run
differ.

Usage (each --set is SECTION.KEY=VALUE of the agent's configuration file):

    .venv/bin/python bench/tune.py                      # the twelve cases, 1200 s each
    .venv/bin/python bench/tune.py --set gains.cycle_s=240 --set patrol.passes_per_sweep=20
    .venv/bin/python bench/tune.py --maps half-algae --starts ahead:1 --duration 600
    .venv/bin/python bench/tune.py --maps random-algae --seeds 1 2 3   # other random maps
    .venv/bin/python bench/tune.py --localization odometry --odom-turn-noise 0.002
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from agent import config as agent_config  # noqa: E402
from deploy import engine  # noqa: E402
from deploy.procs import non_negative  # noqa: E402
from report.thesis import MAPS, PHASE_SSE_RAD, STARTS, WORKLOAD_SSE_M2, thesis_cell  # noqa: E402
from simworld.world import ODOM_NOISE  # noqa: E402

ROBOTS = 3


@dataclass
class Case:
    map: str
    start: str
    duration_s: float
    seed: int
    overrides: dict[str, dict[str, Any]]
    localization: str = "truth"  # or "odometry": the agents steer by dead reckoning
    odom_noise: float = ODOM_NOISE
    odom_turn_noise: float | None = None  # None: as odom_noise (the world's default)


def run_case(case: Case) -> dict[str, Any]:
    """One case in lockstep (``deploy.engine``); its steady-state errors (against ground
    truth, and as the agents saw them) and the robots' true tracks."""
    gmap, tr = engine.run(engine.EngineCase(
        map=case.map, robots=ROBOTS, start=case.start, duration_s=case.duration_s,
        seed=case.seed, overrides=case.overrides, localization=case.localization,
        odom_noise=case.odom_noise, odom_turn_noise=case.odom_turn_noise))
    every = engine.measures(gmap, tr)
    kept = ("phase_sse_rad", "workload_sse_m2", "phase_sse_agents_rad", "workload_sse_agents_m2",
            "phase_path_sse_rad", "workload_rel_sse", "revisit_worst_ratio", "still_frac_max")
    return {
        "map": case.map, "start": case.start, "seed": case.seed,
        "duration_s": case.duration_s,
        "localization": case.localization,
        **{key: every[key] for key in kept},
        "thesis_phase_sse_rad": thesis_cell(PHASE_SSE_RAD, case.map, case.start),
        "thesis_workload_sse_m2": thesis_cell(WORKLOAD_SSE_M2, case.map, case.start),
        "x": tr.x, "y": tr.y,
    }


def parse_set(text: str) -> tuple[str, str, Any]:
    """SECTION.KEY=VALUE, VALUE as JSON (a number, true/false) or else a string."""
    name, sep, raw = text.partition("=")
    section, dot, key = name.partition(".")
    if not sep or not dot or not section or not key:
        raise argparse.ArgumentTypeError(f"{text!r}: expected SECTION.KEY=VALUE")
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        value = raw
    return section, key, value


def ratio(thesis: float, ours: float) -> float:
    return thesis / ours if ours > 0 else math.inf


def times(r: float) -> str:
    """A ratio for the table: a workload error of nearly zero is not '1e14x'."""
    return f"{r:5.1f}x" if r < 1000 else " >999x"


def summary(results: list[dict[str, Any]], seen: str = "") -> str:
    """The range of the ratios to the thesis and how many cells miss the 5x goal;
    ``seen="_agents"`` for the errors as the agents published them."""
    phase_r = [ratio(r["thesis_phase_sse_rad"], r[f"phase_sse{seen}_rad"]) for r in results]
    work_r = [ratio(r["thesis_workload_sse_m2"], r[f"workload_sse{seen}_m2"]) for r in results]
    return (f"phase {min(phase_r):.2f}x to {times(max(phase_r)).strip()} below the thesis, "
            f"workload {min(work_r):.2f}x or more; cells short of 5x: "
            f"phase {sum(r < 5 for r in phase_r)}, workload {sum(r < 5 for r in work_r)}")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--maps", nargs="+", choices=MAPS, default=list(MAPS))
    p.add_argument("--starts", nargs="+", choices=STARTS, default=list(STARTS))
    p.add_argument("--duration", type=float, default=1200.0, metavar="S",
                   help="simulated seconds per case (the suite's 1200)")
    p.add_argument("--seeds", type=int, nargs="+", default=[1], metavar="N",
                   help="map and world seeds; several show how much a cell moves from one "
                        "random map (and odometry draw) to the next")
    p.add_argument("--localization", choices=("truth", "odometry"), default="truth",
                   help="the agents' poses: the simulator's truth, or dead reckoning "
                        "(errors are measured against truth either way)")
    p.add_argument("--odom-noise", type=non_negative, default=ODOM_NOISE, metavar="F",
                   help="odometry distance noise, as btrack sim")
    p.add_argument("--odom-turn-noise", type=non_negative, metavar="F",
                   help="odometry turn noise (default: as --odom-noise), as btrack sim")
    p.add_argument("--set", dest="sets", type=parse_set, action="append", default=[],
                   metavar="SECTION.KEY=VALUE", help="override the agents' configuration")
    p.add_argument("--jobs", type=int, default=2, help="cases at once (processes)")
    p.add_argument("--json", type=Path, metavar="FILE", help="write the results here")
    p.add_argument("--tracks", type=Path, metavar="FILE.npz",
                   help="write every case's true x and y per tick (for comparison)")
    args = p.parse_args(argv)
    if args.duration <= 0 or args.jobs < 1:
        p.error("--duration must be positive and --jobs at least 1")
    overrides: dict[str, dict[str, Any]] = {}
    for section, key, value in args.sets:
        overrides.setdefault(section, {})[key] = value
    try:
        agent_config.load(None, overrides)
    except agent_config.ConfigError as exc:
        p.error(str(exc))
    cases = [Case(mp, st, args.duration, seed, overrides, args.localization, args.odom_noise,
                  args.odom_turn_noise)
             for seed in args.seeds for mp in args.maps for st in args.starts]
    began = time.monotonic()
    results = []
    ctx = multiprocessing.get_context("spawn")
    with ctx.Pool(min(args.jobs, len(cases))) as pool:
        for res in pool.imap(run_case, cases):
            results.append(res)
            print(f"{res['map']:13s} {res['start']:9s} seed {res['seed']:<3d} "
                  f"phase {res['phase_sse_rad']:.4f} rad "
                  f"({times(ratio(res['thesis_phase_sse_rad'], res['phase_sse_rad']))} below)  "
                  f"workload {res['workload_sse_m2']:.4f} m^2 "
                  f"({times(ratio(res['thesis_workload_sse_m2'], res['workload_sse_m2']))} below)"
                  f"  path phase {res['phase_path_sse_rad']:.3f} rad, workload "
                  f"{100 * res['workload_rel_sse']:.2f} %",
                  flush=True)
    for seed in args.seeds if len(args.seeds) > 1 else []:
        print(f"seed {seed}: " + summary([r for r in results if r["seed"] == seed]))
    print(f"{len(results)} cases in {time.monotonic() - began:.0f} s: " + summary(results))
    if args.localization == "odometry":
        print("as the agents saw it (their own phases and workloads): "
              + summary(results, "_agents"))
    if args.json:
        rows = [{k: v for k, v in r.items() if k not in ("x", "y")} for r in results]
        args.json.write_text(json.dumps({"overrides": overrides, "cases": rows}, indent=2))
    if args.tracks:
        arrays = {}
        for r in results:
            name = f"{r['map']}_{r['start']}_seed{r['seed']}"
            arrays[f"{name}_x"], arrays[f"{name}_y"] = r["x"], r["y"]
        np.savez(args.tracks, **arrays)
    return 0


if __name__ == "__main__":
    sys.exit(main())
