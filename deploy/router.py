"""``btrack router``: a Zenoh router in a Python process, for the base station.

There is no ``zenohd`` on PyPI; a session in mode router routes for every client and
enforces the TLS and access control of its configuration file. It holds the session
until SIGTERM or SIGINT.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from typing import Any

from wire.errors import BusError
from wire.session import add_session_args, open_session, options_from_args


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack router",
        description="A Zenoh router (the base station's): robots and the base station's "
        "processes connect to it. Give it its configuration with --zenoh-config "
        "(deploy/render writes zenoh-router.json5), or --listen ENDPOINT.",
    )
    add_session_args(p)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.mode is None:
        args.mode = "router"
    if args.mode != "router":
        print("btrack router: --mode must be router", file=sys.stderr)
        return 2
    stop = threading.Event()

    def on_signal(*_: Any) -> None:
        stop.set()

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, on_signal)
    try:
        session = open_session(options_from_args(args))
    except BusError as exc:  # an endpoint in use, a bad endpoint or certificate: it says
        print(f"btrack router: {exc}", file=sys.stderr)
        return 1
    except Exception as exc:  # what Zenoh raises before a session is tried
        print(f"btrack router: cannot start: {exc}", file=sys.stderr)
        return 1
    print(f"btrack router: {session.info.zid()} routing", flush=True)
    stop.wait()
    closer = threading.Thread(target=session.close, daemon=True)
    closer.start()
    closer.join(3.0)
    return 0
