"""``btrack sim --engine inprocess``: the whole team in this one process
(deploy.engine, the same cores bit for bit as the bus), then its measures, with no
recording: ``summary.json``, ``report.md`` and, round a closed edge, ``map.png`` and
``errors.png``. A closed edge (an island map) runs with truth poses, as over the bus."""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path
from typing import Any

REPORTED = (
    ("phase_sse_rad", "position phase error, mean |e| last quarter (rad)"),
    ("phase_max_rad", "position phase error, max (rad)"),
    ("phase_path_sse_rad", "path-length phase error, mean (rad)"),
    ("workload_sse_m2", "workload error, mean |e| (m^2)"),
    ("workload_rel_sse", "workload error / mean workload"),
    ("workload_rel_max", "workload error / mean workload, max"),
    ("revisit_worst_s", "worst revisit, second half (s)"),
    ("revisit_optimum_s", "optimum worst revisit (s)"),
    ("revisit_worst_ratio", "worst revisit / optimum"),
    ("revisit_worst_ratio_partition", "worst revisit / 2 L / (n v)"),
    ("converge_s", "time to converge (s)"),
)


def refusal(args: argparse.Namespace, closed: bool, localization: str | None
            ) -> str | None:
    """What the in-process engine cannot do of what was asked; None if nothing."""
    given = [name for name, value in (
        ("--fault", args.fault), ("--chaos", args.chaos), ("--kidnap", args.kidnap),
        ("--live", args.live), ("--hil", args.hil), ("--realtime", args.realtime),
        ("--clouds-every", args.clouds_every)) if value]
    if given:
        return f"{', '.join(given)}: the in-process engine has no bus, processes or clock"
    if closed and localization not in (None, "truth"):
        return (f"--localization {localization}: a ring on a closed edge runs with truth"
                " poses only, so far (the laser's view round a floe is later work)")
    return None


def run(args: argparse.Namespace, out: Path, localization: str | None) -> int:
    """Run ``btrack sim``'s case in-process into ``out``; ``localization`` as asked
    (None: truth on a closed edge, pf on an open one, as the bus's default)."""
    from deploy.engine import EngineCase, measures
    from deploy.engine import run as run_case
    from simworld.maps import load_map

    gmap = load_map(args.map, args.scale, args.seed)
    why = refusal(args, gmap.closed, localization)
    if why:
        print(f"btrack sim: {why}")
        return 2
    localization = localization or ("truth" if gmap.closed else "pf")
    overrides: dict[str, dict[str, Any]] = {
        "gains": {k: v for k, v in (("k_s", args.k_s), ("k_phi", args.k_phi),
                                    ("cycle_s", args.cycle_s)) if v is not None},
        "patrol": {"passes_per_sweep": args.passes} if args.passes is not None else {},
    }
    case = EngineCase(map=args.map, robots=args.robots, start=args.start,
                      duration_s=args.duration, seed=args.seed, overrides=overrides,
                      localization=localization, scale=args.scale, config=args.config,
                      change=tuple(args.change))
    wall = time.monotonic()
    try:
        gmap, tracks = run_case(case, gmap)
    except ValueError as exc:  # a gain the ring cannot take, a pose source it has not
        print(f"btrack sim: {exc}")
        return 2
    wall = time.monotonic() - wall
    result = measures(gmap, tracks)
    files = ["summary.json", "report.md"]
    if tracks.s is not None:
        from deploy.engine import ring_edge
        from report.ring import ring_errors, ring_figures

        edge = ring_edge(gmap)  # the measures' own edge, for the errors plot
        assert tracks.d is not None
        errors = ring_errors(tracks.t, tracks.s, tracks.d, tracks.lo, tracks.hi,
                             tracks.direction, tracks.phase, tracks.workload, edge)
        files += ring_figures(gmap, tracks.t, tracks.x, tracks.y, errors, tracks.lo,
                              float(result["workload_mean_m2"]), out)
    changes: list[dict[str, float | None]] = []
    spec = ""
    if tracks.frames:  # the map changed: the errors with the changes marked, as a report's
        from deploy.engine import change_measures
        from report.figures import errors_figure
        from simworld.change import parse_changes, spec_text

        spec = spec_text(parse_changes(args.change))
        errors, rows = change_measures(gmap, tracks)
        changes = [{k: (None if not math.isfinite(v) else v) for k, v in c.items()}
                   for c in rows]
        errors_figure(errors, out / "errors.png", changes=changes)
        files.append("errors.png")
    summary = {
        "engine": "inprocess", "map": gmap.name, "closed": gmap.closed,
        "robots": args.robots, "start": args.start, "duration_s": args.duration,
        "seed": args.seed, "localization": localization, "wall_s": round(wall, 1),
        "measures": {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                     for k, v in result.items()},
        **({"change": spec, "changes": changes} if changes else {}),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    shape = "ring on a closed edge" if gmap.closed else "chain on an open edge"
    lines = [f"# {args.robots} robots, {shape}: {gmap.name}", "",
             f"In-process engine, {localization} poses, {args.duration:g} s, start "
             f"{args.start}, seed {args.seed} ({wall:.0f} s of wall time).", "",
             "| measure | value |", "| --- | --- |"]
    lines += [f"| {label} | {result.get(key, math.nan):.4g} |" for key, label in REPORTED
              if key in result]
    if changes:
        from report.cli import changes_markdown

        lines += changes_markdown(spec, changes).splitlines()
    (out / "report.md").write_text("\n".join(lines) + "\n")
    if not args.quiet:
        print("\n".join(lines[4:]))
        print(f"btrack sim: wrote {', '.join(files)} in {out}")
    return 0
