"""Pieces every bridge process shares: session open/close with a bound, SIGTERM, args."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable, Iterator

import zenoh

from wire.session import SessionOptions, open_session

CLOSE_TIMEOUT_S = 3.0


@contextlib.contextmanager
def bounded_session(opts: SessionOptions) -> Iterator[zenoh.Session]:
    """A session closed on exit, without letting a slow close hang the process."""
    session = open_session(opts)
    try:
        yield session
    finally:
        closer = threading.Thread(target=session.close, daemon=True)
        closer.start()
        closer.join(CLOSE_TIMEOUT_S)
        if closer.is_alive():
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)


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
