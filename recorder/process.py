"""``btrack record``: subscribe to everything in a run namespace and write DIR/run.mcap.

Messages wait in a Zenoh FIFO channel that the main thread empties in batches
through ``recorder.writer.Recording``, stamping each with the wall clock as it is
taken (no Python callback per message); liveliness changes, rare, come through a
callback and a queue. A queryable answers how far the run has got (``Progress``), so
the launcher's progress lines cost no message per tick. The process stops once it has
written a Tick with ``done=True`` (after a short drain for messages in flight) or
on SIGTERM/SIGINT, and always leaves a finished, readable MCAP file.
"""

from __future__ import annotations

import argparse
import json
import queue
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

import zenoh

from recorder.writer import Recording, RunWriter
from wire.codec import encode
from wire.keys import Keys
from wire.session import SessionOptions, add_session_args, bounded_session, options_from_args

CHANNEL_CAPACITY = 1 << 20  # samples held before Zenoh's thread would wait on us
BATCH = 2000  # samples written between looks at liveliness and the stop flag
IDLE_S = 0.002  # sleep when nothing is waiting
DRAIN_CAP_S = 30.0  # the longest a drain goes on past its time while messages keep coming


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="btrack record", description="Record everything on the bus into DIR/run.mcap."
    )
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument(
        "--drain",
        type=float,
        default=0.3,
        metavar="SECONDS",
        help="wall time to keep recording after the final tick (messages in flight)",
    )
    add_session_args(parser)
    return parser.parse_args(argv)


def run(out: Path, opts: SessionOptions, drain_s: float = 0.3) -> dict[str, int]:
    """Record until the final tick or a signal; return the summary counts."""
    keys = Keys(opts.ns)
    out.mkdir(parents=True, exist_ok=True)
    inbox: queue.SimpleQueue[tuple[str, bool, int]] = queue.SimpleQueue()  # liveliness
    stop = threading.Event()

    def on_signal(signum: int, frame: Any) -> None:
        stop.set()

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, on_signal)

    def on_alive(sample: zenoh.Sample) -> None:
        inbox.put((str(sample.key_expr), sample.kind == zenoh.SampleKind.PUT, time.time_ns()))

    writer = RunWriter(out / "run.mcap")
    recording = Recording(writer)
    try:
        with bounded_session(opts, "btrack record") as session:
            # A channel, not a callback: the main thread takes samples in batches with no
            # Python thread woken per message (the recorder sees every message of a run).
            subscriber = session.declare_subscriber(
                keys.everything(), zenoh.handlers.FifoChannel(CHANNEL_CAPACITY)
            )
            alive_sub = session.liveliness().declare_subscriber(
                keys.alive("*"), on_alive, history=True
            )
            progress_q = session.declare_queryable(
                keys.progress(), lambda query: _answer_progress(query, recording))
            token = session.liveliness().declare_token(keys.alive_recorder())
            try:
                _drain_loop(subscriber, inbox, recording, keys, stop, drain_s)
            finally:
                token.undeclare()
                progress_q.undeclare()
                alive_sub.undeclare()
                subscriber.undeclare()
    finally:
        recording.finish()
        writer.close()
    return recording.summary()


def _answer_progress(query: zenoh.Query, recording: Recording) -> None:
    """On a Zenoh thread: the run so far, for a launcher's progress line. Nothing is
    sent per tick: a launcher asks when it prints."""
    progress = recording.progress()
    if progress is not None:
        query.reply(query.key_expr, encode(progress))


def _drain_loop(
    subscriber: zenoh.Subscriber,  # type: ignore[type-arg]
    inbox: queue.SimpleQueue[tuple[str, bool, int]],
    recording: Recording,
    keys: Keys,
    stop: threading.Event,
    drain_s: float,
) -> None:
    relative: dict[str, str] = {}
    deadline: float | None = None
    take = subscriber.try_recv
    while not stop.is_set():
        if deadline is None and recording.done:
            deadline = time.monotonic() + drain_s
        while not inbox.empty():
            key, alive, log_ns = inbox.get_nowait()
            recording.handle_alive(_topic(relative, keys, key), alive, log_ns)
        taken = 0
        while taken < BATCH and (sample := take()) is not None:
            key = str(sample.key_expr)
            recording.handle(_topic(relative, keys, key), sample.payload.to_bytes(),
                             time.time_ns())
            taken += 1
        # The drain ends once its time is up and nothing is waiting: a recorder behind
        # its channel under load takes what came before the time was up (within a cap).
        if deadline is not None:
            late = time.monotonic() - deadline
            if (late >= 0 and not taken) or late >= DRAIN_CAP_S:
                return
        if not taken:
            time.sleep(IDLE_S)


def _topic(relative: dict[str, str], keys: Keys, key: str) -> str:
    topic = relative.get(key)
    if topic is None:
        topic = relative[key] = keys.relative(key)
    return topic


def main(argv: list[str] | None = None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    opts = options_from_args(args)
    try:
        Keys(opts.ns)
    except ValueError as exc:
        print(f"btrack record: {exc}", file=sys.stderr)
        return 2
    counts = run(Path(args.out), opts, args.drain)
    print(json.dumps(counts), flush=True)
    return 0
