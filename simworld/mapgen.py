"""``btrack maps``: write a run of procedural maps (seeds S, S+1, ...) as PNG files in
the thesis's colours, with ``maps.json`` saying what each one is and how to run it."""

from __future__ import annotations

import argparse
import json
import shlex
import sys
from collections.abc import Callable
from pathlib import Path

from simworld.maps import BUILTIN_CELL_M, MapError, write_png
from simworld.procedural import (
    ALGAE,
    AMPLITUDE_RANGE_M,
    CELL_RANGE_M,
    EDGES,
    LENGTH_LIMITS_M,
    LENGTH_RANGE_M,
    MapSpec,
    procedural_map,
)


def _number_in(lo: float, hi: float, unit: str = " m") -> Callable[[str], float]:
    """An argparse type: a float in [lo, hi], refused with the value at fault."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
        if not lo <= value <= hi:
            raise argparse.ArgumentTypeError(f"must be in [{lo:g}, {hi:g}]{unit}, got {text}")
        return value

    return parse


def _int_at_least(lo: int) -> Callable[[str], int]:
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
        if value < lo:
            raise argparse.ArgumentTypeError(f"must be >= {lo}, got {text}")
        return value

    return parse


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack maps",
        description="Write procedural maps (seeds S, S+1, ...) as DIR/procedural-SEED.png, one "
        "pixel per cell in the thesis's colours, and DIR/maps.json listing each map's spec, "
        "scale and the btrack sim line that runs it. Each field not given is drawn from the "
        "seed; a given one replaces the drawn value and leaves the others as they were.",
    )
    p.add_argument(
        "--seed",
        type=_int_at_least(0),
        required=True,
        metavar="S",
        help="the first map's seed (>= 0)",
    )
    p.add_argument(
        "--count",
        type=_int_at_least(1),
        default=1,
        metavar="N",
        help="how many maps, seeds S to S+N-1 (1)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=Path("maps"),
        metavar="DIR",
        help="output directory, made if missing (maps)",
    )
    p.add_argument(
        "--length",
        type=_number_in(*LENGTH_LIMITS_M),
        metavar="M",
        help=f"edge length, {LENGTH_LIMITS_M[0]:g} to {LENGTH_LIMITS_M[1]:g} m (default: "
        f"drawn, {LENGTH_RANGE_M[0]:g} to {LENGTH_RANGE_M[1]:g})",
    )
    p.add_argument(
        "--edge",
        choices=EDGES,
        help="edge shape: straight, sloped (a linear rise of AMPLITUDE end to end) "
        "or curved (a sum of sines, at most AMPLITUDE from its centre line) "
        "(default: drawn)",
    )
    p.add_argument(
        "--amplitude",
        type=_number_in(*AMPLITUDE_RANGE_M),
        metavar="A",
        help=f"the edge's rise or curve amplitude, {AMPLITUDE_RANGE_M[0]:g} to "
        f"{AMPLITUDE_RANGE_M[1]:g} m; 0 for a straight edge (default: drawn)",
    )
    p.add_argument(
        "--algae",
        choices=ALGAE,
        help="algae under the ice: none, steps, ramps, blooms or random (a depth "
        "per 0.1 m), each up to 1.5 m above the local edge (default: drawn)",
    )
    p.add_argument(
        "--cell",
        type=_number_in(*CELL_RANGE_M),
        default=BUILTIN_CELL_M,
        metavar="M",
        help=f"cell size = metres per pixel ({BUILTIN_CELL_M:g}); pass it to btrack sim as --scale",
    )
    return p


def main(argv: list[str] | None = None) -> int:
    p = build_parser()
    args = p.parse_args(argv)
    overrides = {
        name: value
        for name, value in (
            ("length_m", args.length),
            ("edge", args.edge),
            ("amplitude_m", args.amplitude),
            ("algae", args.algae),
        )
        if value is not None
    }
    try:  # a bad combination (a straight edge with an amplitude) before any file
        specs = [
            MapSpec.from_seed(seed, **overrides)
            for seed in range(args.seed, args.seed + args.count)
        ]
    except MapError as exc:
        p.error(str(exc))
    out: Path = args.out
    try:
        out.mkdir(parents=True, exist_ok=True)
        entries = [_write(spec, out, args.cell) for spec in specs]
        (out / "maps.json").write_text(json.dumps({"maps": entries}, indent=1) + "\n")
    except OSError as exc:
        print(f"btrack maps: cannot write into {out}: {exc}", file=sys.stderr)
        return 2
    return 0


def _write(spec: MapSpec, out: Path, cell_m: float) -> dict[str, object]:
    """One map's PNG, its line on stdout and its entry in maps.json."""
    gmap = procedural_map(spec, cell_m)
    path = out / f"procedural-{spec.seed}.png"
    write_png(gmap, path)
    sim = shlex.join(["btrack", "sim", "--map", str(path), "--scale", repr(cell_m)])
    print(f"{path}  {spec.name}  ({gmap.cols} x {gmap.rows} px)")
    return {
        "file": path.name,
        "spec": spec.name,
        "seed": spec.seed,
        "scale": cell_m,
        "length_m": spec.length_m,
        "edge": spec.edge,
        "amplitude_m": spec.amplitude_m,
        "algae": spec.algae,
        "cells": [gmap.cols, gmap.rows],
        "sim": sim,
    }


if __name__ == "__main__":
    raise SystemExit(main())
