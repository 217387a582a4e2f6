"""Pieces every bridge process shares: session open/close with a bound, SIGTERM, args."""

from __future__ import annotations

import argparse
import signal
from collections.abc import Callable


def on_stop(callback: Callable[[], None]) -> None:
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: callback())


def add_epoch_arg(p: argparse.ArgumentParser) -> None:
    p.add_argument("--epoch", type=float,
                   help="the run's epoch, Unix seconds: t = wall clock - epoch (default: now); "
                        "give every process of a run the same value")


def parse_floats(text: str, n: int, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        values = []
    if len(values) != n:
        raise argparse.ArgumentTypeError(f"{what}: expected {n} comma-separated numbers")
    return values
