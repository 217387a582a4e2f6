"""Zenoh session configuration shared by every process.

Precedence, lowest first: zenoh's defaults with peer mode and no shared memory, a
JSON5 file (``--zenoh-config`` or ``ZENOH_CONFIG`` in the environment), then the
command line (``--mode``, ``--connect``, ``--listen``, ``--no-multicast``, ``--lease``).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import re
import sys
import threading
import time
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field

import zenoh

from wire.errors import BusError


@dataclass(frozen=True)
class SessionOptions:
    ns: str = "btrack"
    mode: str | None = None  # peer | client | router; None keeps the file's (or peer)
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    multicast: bool | None = None  # None keeps the file's (or zenoh's default)
    lease_s: float | None = None  # transport lease this session announces
    config_file: str | None = None
    extra: dict[str, str] = field(default_factory=dict)  # json5 path -> json5 value

    def to_args(self) -> list[str]:
        """Command-line arguments that reproduce these options in a child process."""
        args = ["--ns", self.ns]
        if self.mode:
            args += ["--mode", self.mode]
        for ep in self.connect:
            args += ["--connect", ep]
        for ep in self.listen:
            args += ["--listen", ep]
        if self.multicast is False:
            args.append("--no-multicast")
        if self.lease_s is not None:
            args += ["--lease", repr(self.lease_s)]
        if self.config_file:
            args += ["--zenoh-config", self.config_file]
        return args


def add_session_args(parser: argparse.ArgumentParser) -> None:
    group = parser.add_argument_group("bus (Zenoh)")
    group.add_argument("--ns", default="btrack", help="run namespace: every key starts with it")
    group.add_argument("--mode", choices=["peer", "client", "router"], help="default: peer")
    group.add_argument(
        "--connect", action="append", default=[], metavar="ENDPOINT",
        help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)",
    )
    group.add_argument(
        "--listen", action="append", default=[], metavar="ENDPOINT",
        help="endpoint to listen on, e.g. tcp/127.0.0.1:0 (repeatable)",
    )
    group.add_argument(
        "--no-multicast", action="store_true", help="turn off multicast scouting"
    )
    group.add_argument(
        "--lease", type=float, metavar="SECONDS",
        help="transport lease this process announces (how soon peers drop it if frozen)",
    )
    group.add_argument(
        "--zenoh-config", metavar="FILE.json5",
        help="Zenoh configuration file (default: $ZENOH_CONFIG if set)",
    )


def options_from_args(args: argparse.Namespace) -> SessionOptions:
    return SessionOptions(
        ns=args.ns,
        mode=args.mode,
        connect=tuple(args.connect),
        listen=tuple(args.listen),
        multicast=False if args.no_multicast else None,
        lease_s=args.lease,
        config_file=args.zenoh_config,
    )


def build_config(opts: SessionOptions, env: Mapping[str, str] | None = None) -> zenoh.Config:
    environ: Mapping[str, str] = os.environ if env is None else env
    path = opts.config_file or environ.get("ZENOH_CONFIG")
    if path:
        try:
            conf = zenoh.Config.from_file(path)
        except Exception as exc:
            raise SystemExit(f"cannot load Zenoh configuration {path}: {exc}") from None
    else:
        conf = zenoh.Config()
        conf.insert_json5("mode", json.dumps(opts.mode or "peer"))
        # Zenoh 1.x carries a message over 3 KB between processes of one host through a
        # 16 MB shared-memory pool, which every process that receives one maps whole: 16
        # MB more resident in every agent (58 MB against 39 in a team of 3), no faster
        # for our messages (a tick's largest is a few KB). A file may turn it back on.
        conf.insert_json5("transport/shared_memory/enabled", "false")
    if opts.mode:
        conf.insert_json5("mode", json.dumps(opts.mode))
    if opts.connect:
        conf.insert_json5("connect/endpoints", json.dumps(list(opts.connect)))
    if opts.listen:
        conf.insert_json5("listen/endpoints", json.dumps(list(opts.listen)))
    if opts.multicast is not None:
        conf.insert_json5("scouting/multicast/enabled", json.dumps(opts.multicast))
    if opts.lease_s is not None:
        conf.insert_json5("transport/link/tx/lease", str(max(1, int(opts.lease_s * 1000))))
    for key, value in opts.extra.items():
        conf.insert_json5(key, value)
    return conf


# A client tries its router once (Zenoh's default for clients): a robot that boots
# before its base station, or whose first handshake is lost on a lossy radio link,
# would end there. Every process keeps trying this long instead, saying so.
CONNECT_WAIT_S = 60.0
CONNECT_RETRY_S = 1.0


def readable(exc: Exception) -> str:
    """Zenoh's error text without the Rust source locations it carries."""
    return re.sub(r"\s+at \S+\.rs:\d+\.?", "", str(exc)).strip()


def open_session(opts: SessionOptions, wait_s: float = CONNECT_WAIT_S) -> zenoh.Session:
    """A session of ``opts``; while none of its endpoints answers, tried again every
    second for up to ``wait_s`` seconds (one line on stderr when it starts waiting),
    then ``BusError``. Any other error (an endpoint in use, a bad configuration) is a
    ``BusError`` at once."""
    zenoh.try_init_log_from_env()
    deadline = time.monotonic() + wait_s
    told = False
    while True:
        try:
            return zenoh.open(build_config(opts))
        except zenoh.ZError as exc:
            if "Unable to connect" not in str(exc) or time.monotonic() >= deadline:
                raise BusError(f"cannot open the bus: {readable(exc)}") from exc
            if not told:
                where = ", ".join(opts.connect) or (
                    f"the endpoints of {opts.config_file}" if opts.config_file
                    else "its endpoints")
                print(f"btrack: cannot reach {where} yet; trying again every "
                      f"{CONNECT_RETRY_S:g} s for up to {wait_s:g} s", file=sys.stderr,
                      flush=True)
                told = True
            time.sleep(CONNECT_RETRY_S)


CLOSE_TIMEOUT_S = 3.0


def close_within(session: zenoh.Session, timeout_s: float = CLOSE_TIMEOUT_S) -> bool:
    """Close ``session``, waiting at most ``timeout_s`` (a close can block for seconds
    under packet loss or while its router is too loaded to answer); False if it had not
    closed by then, the process going on regardless."""
    closer = threading.Thread(target=session.close, daemon=True)
    closer.start()
    closer.join(timeout_s)
    return not closer.is_alive()


@contextlib.contextmanager
def closed_within(opts: SessionOptions, timeout_s: float = CLOSE_TIMEOUT_S
                  ) -> Iterator[zenoh.Session]:
    """A session, closed on exit with ``close_within``."""
    session = open_session(opts)
    try:
        yield session
    finally:
        close_within(session, timeout_s)


@contextlib.contextmanager
def bounded_session(opts: SessionOptions, who: str = "btrack") -> Iterator[zenoh.Session]:
    """A session closed on exit, without letting a slow close hang the process (it can
    block for seconds under packet loss): past ``CLOSE_TIMEOUT_S`` the process exits."""
    session = open_session(opts)
    try:
        yield session
    finally:
        if not close_within(session, CLOSE_TIMEOUT_S):
            print(f"{who}: session close took over {CLOSE_TIMEOUT_S:g} s; exiting anyway",
                  file=sys.stderr)
            sys.stdout.flush()
            sys.stderr.flush()
            os._exit(0)


def loopback_options(ns: str, hub_port: int, listen: bool = True) -> SessionOptions:
    """Options for a process of a local team: multicast off, connect to the hub on
    loopback, and listen on an ephemeral loopback port so peers can link directly."""
    return SessionOptions(
        ns=ns,
        mode="peer",
        connect=(f"tcp/127.0.0.1:{hub_port}",),
        listen=("tcp/127.0.0.1:0",) if listen else (),
        multicast=False,
    )



def declare_publisher(session: zenoh.Session, key: str) -> zenoh.Publisher:
    """A publisher for our messages: msgpack, never dropped under congestion (BLOCK), so
    the recording holds every tick (a frozen peer can hold it up for at most its lease),
    and batched rather than express: messages put back to back share a frame and a
    wake-up. Measured on a 3-robot lockstep: 19 % less CPU and fewer context switches
    per tick than express, and faster (BENCHMARKS.md)."""
    return session.declare_publisher(
        key,
        encoding=zenoh.Encoding("application/msgpack"),
        congestion_control=zenoh.CongestionControl.BLOCK,
        express=False,
    )
