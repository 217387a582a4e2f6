"""The recording core: payloads in, MCAP records out. No sockets, no threads, no clock.

``RunWriter`` owns the MCAP file (one channel per topic, JSON messages, a JSON schema
per message type); ``Recording`` decodes each payload against the type its topic
implies and writes it, or stores it on ``invalid/<topic>`` with the reason.
The recorder process and the tests that build synthetic runs share this code.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any, BinaryIO

import msgpack
import msgspec
from mcap.writer import CompressionType, Writer

from agent import plausible
from recorder import topics
from wire.codec import DecodeError, decode
from wire.keys import Keys
from wire.messages import AgentState, Progress, Tick, WorldInfo
from wire.tickorder import TickOrder

_dumps = json.JSONEncoder(separators=(",", ":"), allow_nan=False).encode
# A decoded message's fields (finite by its checks) as JSON: the same values as _dumps,
# a dozen times faster (12 us against 0.9 us for a Sense), one of the recorder's largest
# costs per message; _dumps stays for what came undecoded, which may hold a NaN.
_dumps_checked = msgspec.json.Encoder().encode


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


RECENT_TICKS = 8  # each robot's states kept, by tick, for progress: this many and one
REALTIME_END_SLACK_TICKS = 10
# The recorder hears the world's ticks and the agents' states on different links, and
# under load one link can be read seconds behind another: only a tick this far from the
# last Tick is refused (a state of tick 10^9, not one of a busy second).
RECORDER_WINDOW_TICKS = 10_000
DEPTH_SLACK_M = 1.0  # an agent's depth may be this much deeper than the true deepest



class Recording:
    """Decode payloads by topic and write them to a ``RunWriter``; count what fails."""

    def __init__(self, writer: RunWriter) -> None:
        self.writer = writer
        self.messages = 0
        self.invalid = 0
        self.rejected = 0  # well formed but implausible: recorded under rejected/
        self.ticks = 0  # Ticks recorded
        self.info: WorldInfo | None = None  # the run's first WorldInfo
        self._depth_info: WorldInfo | None = None  # the last taken (a changing map's frame)
        self._state_bounds: plausible.Bounds | None = None  # what states are judged by
        self.last_tick: Tick | None = None
        # the world's ticks in order; each with what recording it needs
        self._order: TickOrder[tuple[str, int, Tick, bytes, int]] = TickOrder()
        self.done = False  # a Tick with done=True has been written
        self.last_t_ns = 0  # the latest simulation time seen, for messages without one
        self._routes: dict[str, tuple[type | None, int]] = {}
        # For progress: each robot's recent states by tick, and the latest tick with the
        # states of the newest tick every current robot (one whose newest state is among
        # the newest few ticks) has published, a consistent picture: under load the
        # world's messages, on one link, come far behind the agents' on theirs, and the
        # states of the latest tick heard are long gone. The pair is read from a Zenoh
        # thread: replaced whole, never changed in place.
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
        why = self._implausible(msg)
        if why is not None:
            self.record_invalid(topic, why, payload, log_ns, topics.REJECTED_PREFIX)
            return
        if cls is Tick:
            self._handle_tick(topic, cid, msg, payload, log_ns)
            return
        self._write(cls, cid, msg, log_ns)

    def _handle_tick(self, topic: str, cid: int, tick: Tick, payload: bytes,
                     log_ns: int) -> None:
        """Ticks in order (wire.tickorder): a lost tick is gone past, a forged one
        refused; a tick that skips ahead waits for its own next."""
        out = self._order.offer(tick.k, (topic, cid, tick, payload, log_ns), final=tick.done)
        self._refuse_ticks(out.refused)
        for _, c, t, _, log in out.taken:
            self._write(Tick, c, t, log)

    def _refuse_ticks(self, refused: list[tuple[tuple[str, int, Tick, bytes, int], str]]) -> None:
        for (topic, _, _, payload, log_ns), why in refused:
            self.record_invalid(topic, why, payload, log_ns, topics.REJECTED_PREFIX)

    def finish(self) -> None:
        """The run is over: a tick still waiting for its next is refused."""
        self._refuse_ticks(self._order.finish())

    def _write(self, cls: type, cid: int, msg: Any, log_ns: int) -> None:
        fields: dict[str, Any] = msg.__dict__
        t = fields.get("t")
        if t is not None:
            self.last_t_ns = publish_ns = int(t * 1e9)
        else:
            publish_ns = self.last_t_ns
        self.writer.add(cid, _dumps_checked(fields), log_ns, publish_ns)
        self.messages += 1
        if cls is Tick:
            self.ticks += 1
            self._note_tick(msg)
        elif cls is AgentState:
            recent = self._recent.setdefault(msg.robot, {})
            recent[msg.k] = msg
            if len(recent) > RECENT_TICKS + 1:  # the oldest goes: a state forged for a
                del recent[min(recent)]  # far tick must not push the real ones out

    def _implausible(self, msg: Any) -> str | None:
        """Why a well-formed message cannot be the run's own (agent.plausible for the
        world's clock and the agents' states), None if it can be: the recording and the
        report must not take a forged final tick or a state from the future as true."""
        if isinstance(msg, WorldInfo):
            return self._info_problem(msg)
        info = self.info
        if isinstance(msg, Tick):
            if info is not None:  # its order is judged in _handle_tick
                if abs(msg.t - msg.k * info.dt) > 1e-6 * max(1.0, msg.t):
                    return f"t = {msg.t:g} s is not tick {msg.k} of {info.dt:g} s"
                # (a hardware loop's ticks count from its epoch: it begins at first_k)
                final = info.first_k + round(info.duration_s / info.dt) - 1
                # A world on the wall clock ends when its time is up: near, not at, it.
                slack = REALTIME_END_SLACK_TICKS if info.realtime else 0
                if msg.k > final + slack:
                    return f"tick {msg.k} after the run's last tick, {final}"
                if msg.done and msg.k < final - slack:
                    return f"done at tick {msg.k}; the run's last tick is {final}"
            return None
        if isinstance(msg, AgentState) and self._state_bounds is not None:
            newest = self.last_tick.k if self.last_tick else None
            return plausible.state_problem(msg, self._state_bounds, newest,
                                           RECORDER_WINDOW_TICKS, RECORDER_WINDOW_TICKS)
        return None

    def _info_problem(self, msg: WorldInfo) -> str | None:
        """Why a WorldInfo cannot be the run's world, None if it can (and is taken). A
        second one must have the first's edge and tick; its depth profile may differ
        only on a map that changes (the first declared its changes, this one the same),
        from a later time than the last one's, in a change's window, not ahead of the
        clock."""
        first = self.info
        if first is None:
            self.info = self._depth_info = msg
            self._widen_bounds(msg)
            return None
        if ((msg.edge_lo, msg.edge_hi, msg.dt, msg.closed, msg.contour)
                != (first.edge_lo, first.edge_hi, first.dt, first.closed, first.contour)):
            return "a second world with another edge or tick"
        if (msg.change, msg.change_windows) != (first.change, first.change_windows):
            return "a second world with other changes of the map"
        last = self._depth_info or first
        if msg.patrol_depth == last.patrol_depth and msg.edge_y == last.edge_y:
            return None
        if not first.change_windows:
            return "a second world with another depth profile; this run's map does not change"
        if len(msg.patrol_depth) != len(first.patrol_depth) or msg.edge_y != first.edge_y:
            return "a changed map with other bins or another edge shape"
        if msg.depth_t < last.depth_t:
            return f"a depth profile from t = {msg.depth_t:g} s, before the last one's"
        w = first.change_windows
        if not any(w[i] - 1e-9 <= msg.depth_t <= w[i + 1] + 1e-9 for i in range(0, len(w), 2)):
            return f"a depth profile from t = {msg.depth_t:g} s, in no window of the changes"
        now = self.last_tick.t if self.last_tick is not None else 0.0
        if msg.depth_t > now + RECORDER_WINDOW_TICKS * first.dt:
            return f"a depth profile from t = {msg.depth_t:g} s, ahead of the clock ({now:g} s)"
        self._depth_info = msg
        self._widen_bounds(msg)
        return None

    def _widen_bounds(self, msg: WorldInfo) -> None:
        """The agents' states are judged against the deepest true depth so far."""
        deepest = max(msg.patrol_depth, default=0.0) + DEPTH_SLACK_M
        if self._state_bounds is None or deepest > self._state_bounds.depth_max:
            # on a ring the agents' bins are of their own depth maps, not the world's:
            # the recorder, which acts on no depth, does not judge them there
            self._state_bounds = plausible.Bounds(
                msg.edge_lo, msg.edge_hi, deepest, msg.bin_m, plausible.NO_PASS_LIMIT,
                closed=msg.closed, reach_m=math.inf)

    def _note_tick(self, tick: Tick) -> None:
        self.last_tick = tick
        if tick.done:
            self.done = True
        self.latest = (tick, self._newest_common())

    def _newest_common(self) -> dict[int, AgentState]:
        """The states of the newest tick that every current robot has a state of: of the
        ticks up to the lower median of the robots' newest (one state forged for a tick
        far ahead, which the window lets in, must not make the others look stopped), the
        robots with one among the last few of them."""
        newest = sorted(max(recent) for recent in self._recent.values() if recent)
        if not newest:
            return {}
        top = newest[(len(newest) - 1) // 2]
        current = [robot for robot, recent in self._recent.items()
                   if any(top - RECENT_TICKS <= k <= top for k in recent)]
        common = set.intersection(*(set(self._recent[robot]) for robot in current))
        common = {k for k in common if k <= top}
        if not common:
            return {}
        k = max(common)
        return {robot: self._recent[robot][k] for robot in current}

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

    def record_invalid(self, topic: str, reason: str, payload: bytes, log_ns: int,
                       prefix: str = topics.INVALID_PREFIX) -> None:
        """Store a message that is malformed (``invalid/``) or implausible (``rejected/``)
        with the reason, apart from the run's own."""
        cid = self.writer.channel(prefix + topic, "invalid", topics.INVALID_SCHEMA)
        data = _dumps({"error": reason, "hex": bytes(payload[:64]).hex()}).encode()
        self.writer.add(cid, data, log_ns, self.last_t_ns)
        if prefix == topics.INVALID_PREFIX:
            self.invalid += 1
        else:
            self.rejected += 1

    def handle_alive(self, topic: str, alive: bool, log_ns: int) -> None:
        """Record a liveliness token appearing or going away on ``topic``; one of a
        robot the world does not have is recorded as rejected."""
        robot = Keys.robot_of(topic)
        if (robot is not None and self.info is not None and not 0 <= robot < self.info.robots
                and alive):
            self.record_invalid(topic, f"no robot {robot} in this run (0..{self.info.robots - 1})",
                                b"", log_ns, topics.REJECTED_PREFIX)
            return
        cid = self.writer.channel(topic, "alive", topics.ALIVE_SCHEMA)
        self.writer.add(cid, _dumps({"alive": alive}).encode(), log_ns, self.last_t_ns)
        self.messages += 1

    def progress(self) -> Progress | None:
        """The run so far as recorded: the latest tick, and the current robots' phases
        and workloads of the newest tick they all published; None before the first
        tick."""
        if self.latest is None:
            return None
        tick, states = self.latest
        robots = sorted(states)
        return Progress(tick.t, tick.k, tick.live, tick.wall_ns, tick.done, robots,
                        [states[r].phase for r in robots], [states[r].workload for r in robots],
                        states[robots[0]].t if robots else -1.0)

    def summary(self) -> dict[str, int]:
        last = self.last_tick
        return {"messages": self.messages, "invalid": self.invalid, "rejected": self.rejected,
                "done": self.done, "ticks": self.ticks, "lost_ticks": self._order.lost,
                "last_k": -1 if last is None else last.k}
