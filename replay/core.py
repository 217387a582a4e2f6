"""What a replay puts on the bus, and when: pure, no file, no socket, no clock.

A recording holds each message as JSON (``recorder.writer``); the bus carries msgpack
(``wire.codec``). ``payload_of`` turns one back into the other, field for field (JSON
keeps every float exactly), so a replayed message is the bytes its sender put.
``Pacer`` says when each message is due: at the recorded pace (log times, scaled by a
speed), or as fast as a listener takes them, never more than a few ticks ahead of the
last tick it answered.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass

import msgpack

from recorder import topics
from wire.codec import encode, from_record

SKIPPED_PREFIXES = (topics.INVALID_PREFIX, topics.REJECTED_PREFIX, "alive/")


def replayable(topic: str) -> bool:
    """A topic of the run's own messages: not the Foxglove view (derived; it starts with
    "/"), not what the recorder refused, not liveliness (a token, not a message)."""
    return not topic.startswith("/") and not topic.startswith(SKIPPED_PREFIXES)


def payload_of(topic: str, data: bytes) -> tuple[bytes, int | None]:
    """The msgpack payload of a recorded message's JSON, and its tick (None if it has
    none). A message of a known type is rebuilt as that type, so a field that is not
    the type's own fails here (``DecodeError``), not at its listener."""
    fields = json.loads(data)
    cls = topics.message_type(topic)
    if cls is not None:
        payload = encode(from_record(cls, fields))
    else:  # a msgpack map on a topic of no known type, as it came
        payload = msgpack.packb(fields, use_bin_type=True)
    k = fields.get("k") if isinstance(fields, dict) else None
    return payload, k if isinstance(k, int) and not isinstance(k, bool) else None


@dataclass(frozen=True)
class Item:
    topic: str
    log_ns: int  # when the recorder took it
    k: int | None
    payload: bytes


def due_s(items: Iterable[Item], speed: float) -> list[float]:
    """Seconds from the replay's start at which each item is due, at ``speed`` times
    the recorded pace (the recorder's log times)."""
    items = list(items)
    if not items:
        return []
    first = items[0].log_ns
    return [max(0.0, (it.log_ns - first) / 1e9 / speed) for it in items]


class Pacer:
    """As fast as a listener takes them: tick k's messages go out once the listener has
    answered tick k - ``ahead`` (or before it has answered anything, the first
    ``ahead`` ticks). Fed with the ticks the listener publishes."""

    def __init__(self, ahead: int) -> None:
        if ahead < 1:
            raise ValueError("ahead must be at least 1 tick")
        self.ahead = ahead
        self.first_k: int | None = None  # the first tick replayed
        self.answered = -1  # the highest tick the listener has answered

    def heard(self, k: int) -> None:
        self.answered = max(self.answered, k)

    def may_send(self, k: int | None) -> bool:
        if k is None:
            return True
        if self.first_k is None:
            self.first_k = k
        return k - self.ahead <= max(self.answered, self.first_k - 1)
