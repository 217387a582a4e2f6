"""``btrack replay RUN.mcap``: a recording's messages back on the bus, in the order the
recorder took them, so a localizer, a recorder or a report can be run again on a
recorded run (a real robots' run included).

By default at the recorded pace (``--speed`` scales it); ``--fast`` as fast as the
listeners take them, losing none: every publisher blocks rather than drops (as every
btrack publisher does), and with ``--pace-on KEY`` tick k goes out only once a
listener has put a message of tick k - ``--ahead`` on KEY: with the default, 1, the
listener hears tick k + 1 only after it has answered tick k, as in the lockstep, so it
gets every tick's messages whole and in order and computes what it computed live.
``--wait-for TOKEN`` waits for the listeners' liveliness tokens before the first
message. Prints the count of messages put per topic as its last line.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from collections import Counter
from functools import partial
from pathlib import Path

import msgpack
import zenoh

from replay.core import Item, Pacer, due_s, payload_of, replayable
from wire.keys import Keys
from wire.session import add_session_args, bounded_session, declare_publisher, options_from_args

STARTUP_S = 30.0


class ReplayError(Exception):
    """The recording cannot be replayed as asked (missing, not MCAP, nothing selected)."""


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack replay",
        description="Put a recording's messages back on the bus, in the order they were "
        "recorded: at the recorded pace, or as fast as the listeners take them.")
    p.add_argument("run", metavar="RUN.mcap", help="a recording, or the run directory holding one")
    p.add_argument("--topics", nargs="+", metavar="KEYEXPR",
                   help="only these topics (key expressions without the namespace, e.g. "
                   "'robot/*/sense' laser/scan 'world/**'); default every message of the run")
    p.add_argument("--speed", type=float, default=1.0, metavar="X",
                   help="X times the recorded pace (default 1)")
    p.add_argument("--fast", action="store_true",
                   help="as fast as the listeners take them (see --pace-on)")
    p.add_argument("--pace-on", metavar="KEYEXPR",
                   help="with --fast: send tick k once a message of tick k - AHEAD came on "
                   "this key (e.g. 'robot/*/pose' for a localizer)")
    p.add_argument("--ahead", type=int, default=1, metavar="TICKS",
                   help="with --pace-on: ticks sent ahead of the listener's answer (1: "
                   "the lockstep's; more is faster, but a listener whose subscriptions "
                   "each deliver on a thread of their own, as zenoh-python's callbacks "
                   "do, can then hear tick k + 1's scan before tick k's last sensing)")
    p.add_argument("--wait-for", action="append", default=[], metavar="TOKEN",
                   help="a liveliness token to wait for before the first message, e.g. "
                   "alive/localizer, alive/recorder (repeatable)")
    p.add_argument("--settle", type=float, default=0.5, metavar="SECONDS",
                   help="wall seconds between meeting the listeners and the first message, "
                   "for their subscriptions to reach us (0.5, as the world's)")
    p.add_argument("--pace-timeout", type=float, default=30.0, metavar="SECONDS",
                   help="give up when the listener has not answered for this long (30)")
    add_session_args(p)
    return p


def load_items(path: Path, patterns: list[str] | None) -> list[Item]:
    """The recording's replayable messages (those of ``patterns`` if given), in the
    order the recorder took them; raises ``ReplayError``."""
    from mcap.reader import make_reader

    if path.is_dir():
        path = path / "run.mcap"
    if not path.is_file():
        raise ReplayError(f"no recording at {path}")
    selectors = [zenoh.KeyExpr(p) for p in patterns] if patterns else None
    chosen: dict[str, bool] = {}
    items: list[Item] = []
    try:
        with open(path, "rb") as stream:
            reader = make_reader(stream)
            for _, channel, message in reader.iter_messages(log_time_order=True):
                topic = channel.topic
                keep = chosen.get(topic)
                if keep is None:
                    keep = chosen[topic] = replayable(topic) and (
                        selectors is None
                        or any(s.intersects(zenoh.KeyExpr(topic)) for s in selectors))
                if keep:
                    payload, k = payload_of(topic, message.data)
                    items.append(Item(topic, message.log_time, k, payload))
    except ReplayError:
        raise
    except Exception as exc:  # the reader raises many types on what is not MCAP
        raise ReplayError(f"cannot read {path}: {type(exc).__name__}: {exc}") from None
    if not items:
        raise ReplayError(f"nothing to replay in {path}"
                          + (f" on {' '.join(patterns)}" if patterns else ""))
    return items


def _wait_tokens(session: zenoh.Session, keys: Keys, tokens: list[str]) -> str | None:
    """Wait for each liveliness token; the first missing after STARTUP_S, or None."""
    deadline = time.monotonic() + STARTUP_S
    for token in tokens:
        key = f"{keys.ns}/{token}"
        while True:
            replies = list(session.liveliness().get(key, timeout=1.0))
            if any(r.ok is not None for r in replies):
                break
            if time.monotonic() > deadline:
                return token
            time.sleep(0.1)
    return None


def _matched(publisher: zenoh.Publisher) -> bool:
    """Whether some subscriber matches (a MatchingStatus at run time, a bool in the
    stubs)."""
    status: object = publisher.matching_status
    return bool(getattr(status, "matching", status))


def replay(session: zenoh.Session, keys: Keys, items: list[Item], args: argparse.Namespace
           ) -> Counter[str]:
    """Put every item; the count put per topic."""
    pacer = Pacer(args.ahead) if args.fast and args.pace_on else None
    answered = threading.Condition()

    def on_answer(sample: zenoh.Sample) -> None:
        try:
            k = msgpack.unpackb(sample.payload.to_bytes(), raw=False).get("k")
        except Exception:
            return  # not one of ours: it answers nothing
        if isinstance(k, int) and pacer is not None:
            with answered:
                pacer.heard(k)
                answered.notify_all()

    sub = (session.declare_subscriber(f"{keys.ns}/{args.pace_on}", on_answer)
           if pacer is not None else None)
    publishers = {topic: declare_publisher(session, f"{keys.ns}/{topic}")
                  for topic in dict.fromkeys(it.topic for it in items)}
    # Every key heard by someone before the first put, then a settle (as the world's
    # before tick 0): a subscription seen by liveliness alone can still be on its way,
    # and the peers' direct links come up just after they meet.
    deadline = time.monotonic() + STARTUP_S
    while args.wait_for and not all(map(_matched, publishers.values())):
        if time.monotonic() > deadline:
            unheard = [t for t, p in publishers.items() if not _matched(p)]
            raise ReplayError(f"nobody subscribes to {', '.join(unheard)}")
        time.sleep(0.05)
    time.sleep(args.settle)
    sent: Counter[str] = Counter()
    due = None if args.fast else due_s(items, args.speed)
    began = time.monotonic()
    try:
        for i, item in enumerate(items):
            if due is not None:
                wait = began + due[i] - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            elif pacer is not None:
                with answered:
                    if not answered.wait_for(partial(pacer.may_send, item.k),
                                             args.pace_timeout):
                        raise ReplayError(
                            f"no message on {args.pace_on} of tick {item.k - args.ahead} or "
                            f"later within {args.pace_timeout:g} s (its last: tick "
                            f"{pacer.answered}): is its listener running?")
            publishers[item.topic].put(item.payload)
            sent[item.topic] += 1
        # The listener's answer to the last tick too, before the session closes: what
        # the last tick set off is then on the bus, not still in a listener's hands.
        last_k = max((it.k for it in items if it.k is not None), default=None)
        if pacer is not None and last_k is not None:
            with answered:
                if not answered.wait_for(lambda: pacer.answered >= last_k, args.pace_timeout):
                    raise ReplayError(
                        f"no message on {args.pace_on} of the last tick, {last_k}, within "
                        f"{args.pace_timeout:g} s (its last: tick {pacer.answered})")
    finally:
        if sub is not None:
            sub.undeclare()
    return sent


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    opts = options_from_args(args)
    try:
        keys = Keys(opts.ns)
    except ValueError as exc:
        print(f"btrack replay: {exc}", file=sys.stderr)
        return 2
    if not args.fast and not args.speed > 0:
        print(f"btrack replay: --speed must be positive, not {args.speed:g} (or --fast)",
              file=sys.stderr)
        return 2
    if args.pace_on and not args.fast:
        print("btrack replay: --pace-on goes with --fast", file=sys.stderr)
        return 2
    if args.ahead < 1:
        print(f"btrack replay: --ahead must be at least 1, not {args.ahead}", file=sys.stderr)
        return 2
    try:
        items = load_items(Path(args.run), args.topics)
    except ReplayError as exc:
        print(f"btrack replay: {exc}", file=sys.stderr)
        return 2
    began = time.monotonic()
    with bounded_session(opts, "btrack replay") as session:
        missing = _wait_tokens(session, keys, args.wait_for)
        if missing is not None:
            print(f"btrack replay: no {missing} token on {keys.ns} within {STARTUP_S:g} s",
                  file=sys.stderr)
            return 1
        try:
            sent = replay(session, keys, items, args)
        except ReplayError as exc:
            print(f"btrack replay: {exc}", file=sys.stderr)
            return 1
    print(json.dumps({"messages": sum(sent.values()), "topics": dict(sorted(sent.items())),
                      "seconds": round(time.monotonic() - began, 2)}), flush=True)
    return 0
