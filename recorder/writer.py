"""The recording core: payloads in, MCAP records out. No sockets, no threads, no clock.

``RunWriter`` owns the MCAP file (one channel per topic, JSON messages, a JSON schema
per message type); ``Recording`` decodes each payload against the type its topic
implies and writes it, or stores it on ``invalid/<topic>`` with the reason.
The recorder process and the tests that build synthetic runs share this code.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, BinaryIO

import msgpack
from mcap.writer import CompressionType, Writer

from recorder import topics
from wire.codec import DecodeError, decode
from wire.messages import AgentState, Progress, Tick

_dumps = json.JSONEncoder(separators=(",", ":"), allow_nan=False).encode


class RunWriter:
    """An MCAP file being written: channels are made on first use of a topic."""

    def __init__(self, path: str | Path, library: str = "btrack recorder") -> None:
        self.path = Path(path)
        self._stream: BinaryIO = open(self.path, "wb")  # noqa: SIM115 - closed in close()
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library=library)
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.closed = False

    def channel(self, topic: str, schema_name: str, schema: bytes) -> int:
        """The channel id of ``topic``, registering it (and its schema) on first use."""
        cid = self._channels.get(topic)
        if cid is None:
            sid = self._schemas.get(schema_name)
            if sid is None:
                sid = self._writer.register_schema(
                    name=schema_name, encoding="jsonschema", data=schema
                )
                self._schemas[schema_name] = sid
            cid = self._writer.register_channel(topic=topic, message_encoding="json", schema_id=sid)
            self._channels[topic] = cid
        return cid

    def add(self, channel_id: int, data: bytes, log_ns: int, publish_ns: int) -> None:
        self._writer.add_message(
            channel_id=channel_id, log_time=log_ns, data=data, publish_time=publish_ns
        )

    def close(self) -> None:
        """Write the summary and close the file (idempotent)."""
        if self.closed:
            return
        self.closed = True
        try:
            self._writer.finish()
        finally:
            self._stream.close()


RECENT_TICKS = 8  # each robot's states kept, by tick, for progress


class Recording:
    """Decode payloads by topic and write them to a ``RunWriter``; count what fails."""

    def __init__(self, writer: RunWriter) -> None:
        self.writer = writer
        self.messages = 0
        self.invalid = 0
        self.done = False  # a Tick with done=True has been written
        self.last_t_ns = 0  # the latest simulation time seen, for messages without one
        self._routes: dict[str, tuple[type | None, int]] = {}
        # For progress: each robot's recent states by tick, and the latest tick with the
        # states of that tick (or the latest before it), a consistent picture. The pair
        # is read from a Zenoh thread: replaced whole, never changed in place.
        self._recent: dict[int, dict[int, AgentState]] = {}
        self.latest: tuple[Tick, dict[int, AgentState]] | None = None

    def _route(self, topic: str) -> tuple[type | None, int]:
        cls = topics.message_type(topic)
        if cls is None:
            cid = self.writer.channel(topic, "unknown", topics.GENERIC_SCHEMA)
        else:
            cid = self.writer.channel(topic, cls.__name__, topics.schema_of(cls))
        route = (cls, cid)
        self._routes[topic] = route
        return route

    def handle(self, topic: str, payload: bytes, log_ns: int) -> None:
        """Record one payload received on ``topic`` (the key without the namespace)."""
        route = self._routes.get(topic)
        if route is None:
            route = self._route(topic)
        cls, cid = route
        if cls is None:
            self._handle_unknown(topic, cid, payload, log_ns)
            return
        try:
            msg: Any = decode(cls, payload)
        except DecodeError as exc:
            self.record_invalid(topic, str(exc), payload, log_ns)
            return
        fields: dict[str, Any] = msg.__dict__
        t = fields.get("t")
        if t is not None:
            self.last_t_ns = publish_ns = int(t * 1e9)
        else:
            publish_ns = self.last_t_ns
        self.writer.add(cid, _dumps(fields).encode(), log_ns, publish_ns)
        self.messages += 1
        if cls is Tick:
            self._note_tick(msg)
        elif cls is AgentState:
            recent = self._recent.setdefault(msg.robot, {})
            recent[msg.k] = msg
            for old in [k for k in recent if k < msg.k - RECENT_TICKS]:
                del recent[old]

    def _note_tick(self, tick: Tick) -> None:
        if tick.done:
            self.done = True
        states = {}
        for robot, recent in self._recent.items():
            ks = [k for k in recent if k <= tick.k]
            if ks:
                states[robot] = recent[max(ks)]
        self.latest = (tick, states)

    def _handle_unknown(self, topic: str, cid: int, payload: bytes, log_ns: int) -> None:
        try:
            raw = msgpack.unpackb(payload, raw=False)
            if not isinstance(raw, dict):
                raise ValueError(f"expected a map, got {type(raw).__name__}")
            data = _dumps(raw).encode()
        except Exception as exc:  # garbage of any kind is recorded, never raised
            self.record_invalid(topic, f"unknown topic, not a msgpack map: {exc}", payload, log_ns)
            return
        self.writer.add(cid, data, log_ns, self.last_t_ns)
        self.messages += 1

    def record_invalid(self, topic: str, reason: str, payload: bytes, log_ns: int) -> None:
        cid = self.writer.channel(topics.INVALID_PREFIX + topic, "invalid", topics.INVALID_SCHEMA)
        data = _dumps({"error": reason, "hex": bytes(payload[:64]).hex()}).encode()
        self.writer.add(cid, data, log_ns, self.last_t_ns)
        self.invalid += 1

    def handle_alive(self, topic: str, alive: bool, log_ns: int) -> None:
        """Record a liveliness token appearing or going away on ``topic``."""
        cid = self.writer.channel(topic, "alive", topics.ALIVE_SCHEMA)
        self.writer.add(cid, _dumps({"alive": alive}).encode(), log_ns, self.last_t_ns)
        self.messages += 1

    def progress(self) -> Progress | None:
        """The run so far as recorded: the latest tick and every robot's latest phase
        and workload; None before the first tick."""
        if self.latest is None:
            return None
        tick, states = self.latest
        robots = sorted(states)
        return Progress(tick.t, tick.k, tick.live, tick.wall_ns, tick.done, robots,
                        [states[r].phase for r in robots], [states[r].workload for r in robots])

    def summary(self) -> dict[str, int]:
        return {"messages": self.messages, "invalid": self.invalid, "done": self.done}
