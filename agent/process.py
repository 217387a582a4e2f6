"""``btrack agent``: one robot's controller as its own process.

It hears its own robot (sense, pose) and the states of its two neighbours (the
nearest live lower and higher ids, from Zenoh liveliness), feeds what it hears to
the membership core (agent.membership), which decides whether each tick acts, waits
or stands still, runs the control core and publishes its state and its robot's
command. Malformed messages
are counted and dropped; nothing on the bus can kill it.

On a closed edge (its Sense says so) the team is a ring: the agent waits for the
world's WorldInfo with the edge's contour, builds its edge frame from it and runs a
``RingController`` (agent.ringcontrol), its neighbours the nearest live ids round the
ring; the first contour whose length is the Sense's edge is taken, an unlike one later
refused.
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import json
import math
import os
import queue
import signal
import sys
import time
import traceback
from collections.abc import Callable
from typing import Any

import zenoh

from agent import config as agent_config
from agent import plausible
from agent.controller import Controller, Neighbour
from agent.edgeframe import ClosedEdge
from agent.membership import HISTORY, Decision, Membership
from agent.ring import ring_bins
from agent.ringcontrol import RingController
from agent.stability import check_gains
from agent.team import passes_for
from wire import AgentState, Cmd, DecodeError, Keys, Pose, Sense, WorldInfo, decode, encode
from wire.session import add_session_args, declare_publisher, open_session, options_from_args

DEFAULT_LEASE_S = 1.0  # lease an agent announces unless told otherwise
PARKED_STATES = 256  # neighbour states kept for ticks we have no sensing of yet, at most
COPIES_PARKED = 4  # unlike states of one neighbour's tick kept to be judged, at most
MEMBERS_TIMEOUT_S = 2.0  # how long the start-up question "who is alive?" may take


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack agent",
        description="One robot's controller (meant for the robot's own computer): hears its "
        "robot and its two neighbours, balances workload and phase, commands its robot.",
    )
    p.add_argument("--id", type=int, required=True, help="this robot's id (0-based)")
    p.add_argument("--robots", type=int, required=True,
                   help="team size: sets the initial equal segment and the gain check")
    p.add_argument("--config", metavar="FILE.toml",
                   help="[gains], [patrol] and [limits] tables (see README)")
    p.add_argument("--k-s", type=float, help="workload gain K_s (eq. 4.3)")
    p.add_argument("--k-phi", type=float, help="phase consensus gain K_phi (eq. 4.7)")
    p.add_argument("--cycle-s", type=float,
                   help="fix the common cycle period, s (default: from the team's need)")
    p.add_argument("--passes", type=int,
                   help="at least this many passes per sweep of a segment (more on long ones)")
    p.add_argument("--sensor-latency", type=float, metavar="S",
                   help="how late the ice and algae readings are, s (the data sheet's; "
                   "edges found are placed back by it)")
    p.add_argument("--sensor-band", type=float, metavar="M",
                   help="the ice and algae comparators' dead band, m (the whole band)")
    p.add_argument("--max-depth", type=float, default=2.0,
                   help="deepest patrol expected, m, for the K_s stability check")
    p.add_argument("--neighbour-timeout", type=float, default=1.0,
                   help="wall seconds to wait for a live neighbour's previous state")
    p.add_argument("--token-grace", type=float, default=0.0, metavar="S",
                   help="keep a neighbour whose liveliness token goes while its states "
                   "come, until a tick has waited S wall s for one (a fleet behind "
                   "meshed routers, whose robots change router; default 0: drop it)")
    add_session_args(p)
    return p


class RingGainsError(ValueError):
    """Gains that are stable on the team's chain but not on its ring."""


class AgentNode:
    """The shell around one Controller and its Membership: subscriptions, the tick loop."""

    def __init__(self, session: zenoh.Session, keys: Keys, robot: int, team: int,
                 gains: Any, patrol: Any, limits: Any, neighbour_timeout: float,
                 max_depth_m: float = 2.0, token_grace_s: float = 0.0):
        self.session = session
        self.keys = keys
        self.robot = robot
        self.team = team
        self.max_depth_m = max_depth_m
        self.gains, self.patrol_cfg, self.limits = gains, patrol, limits
        self.membership: Membership[AgentState] = Membership(
            robot, team, neighbour_timeout, token_grace_s=token_grace_s)
        # Every message in arrival order; a token in ``wake`` for each wake-up wanted.
        self.inbox: collections.deque[tuple[str, Any]] = collections.deque()
        self.wake: queue.SimpleQueue[None] = queue.SimpleQueue()
        self.waiting = False  # a tick has begun (its Sense is here): anything may finish it
        self.neighbour_subs: dict[int, Any] = {}
        self.found = 0  # neighbours taken for live by their states, their tokens not up
        self.sense: Sense | None = None
        self.pose: Pose | None = None
        # by tick: with hardware a tick's Pose can come after the next tick's Sense
        self.senses: dict[int, Sense] = {}
        self.poses: dict[int, Pose] = {}
        self.dropped = 0
        self.rejected = 0
        self.ticks = 0
        self.timeouts = 0  # ticks acted on without a neighbour's state, its wait over
        # faults of our own (an exception from a core on a message or a tick, which the
        # checks let through): counted and logged; the robot is told to stand still for
        # that tick and the controller goes on with the next
        self.faults = 0
        self.halted_k = -1  # the last tick given up on for a fault
        # What a neighbour's state is judged by (agent.plausible): the edge and limits, set
        # from the first Sense; our newest tick; our own recent claims by tick; and the
        # states of ticks we have no sensing of yet (all of them before the first Sense),
        # by (robot, k), waiting to be judged.
        self.bounds: plausible.Bounds | None = None
        self.newest_k = -1
        self.claims: dict[int, plausible.Claim] = {}
        self.parked: dict[tuple[int, int], list[tuple[str, AgentState]]] = {}
        # A neighbour's state of tick k that came before its state of k-1 (one we have
        # heard from before), kept until that one comes (then judged by the law from it)
        # or until we decide tick k+1, the first that needs it (then judged without it):
        # judged at once, a forgery sent early would meet only the looser check
        # (agent.plausible) and could stand in for the real state of k, not here yet.
        self.awaiting: dict[tuple[int, int], list[tuple[str, AgentState]]] = {}
        self.controller: Controller | None = None
        # A closed edge: whether the sensing says so, and the edge frame built from the
        # world's contour (None until a WorldInfo with one has come; ticks wait for it)
        self.closed = False
        self.contour: list[float] | None = None
        self.ring_edge: ClosedEdge | None = None
        self.stopping = False
        self.pub_state = declare_publisher(session, keys.state(robot))
        self.pub_cmd = declare_publisher(session, keys.cmd(robot))
        self.subs = [
            session.declare_subscriber(keys.sense(robot), self._on("sense")),
            session.declare_subscriber(keys.pose(robot), self._on("pose")),
            session.declare_subscriber(keys.world_info(), self._on("info")),
            session.liveliness().declare_subscriber(
                keys.alive("*"), self._on_alive, history=True
            ),
        ]
        self.token = session.liveliness().declare_token(keys.alive(robot))

    # Zenoh callbacks run on Zenoh's threads: they only enqueue. A Sense begins a tick
    # and always wakes the loop; a Pose or a neighbour's State wakes it only while a
    # tick is waiting (otherwise it waits in the inbox for the next Sense): one wake-up
    # per tick in lockstep instead of one per message. The callback appends before it
    # reads ``waiting`` and the loop sets ``waiting`` before it looks at the inbox, so
    # no message is left sleeping while a tick waits for it.
    def _on(self, kind: str) -> Callable[[zenoh.Sample], None]:
        always = kind == "sense"

        def callback(sample: zenoh.Sample) -> None:
            self.inbox.append((kind, (str(sample.key_expr), sample.payload.to_bytes())))
            if always or self.waiting:
                self.wake.put(None)
        return callback

    def _post(self, kind: str, data: Any) -> None:
        self.inbox.append((kind, data))
        self.wake.put(None)

    def _on_alive(self, sample: zenoh.Sample) -> None:
        rid = Keys.robot_of(str(sample.key_expr))
        if rid is not None:
            self._post("alive", (rid, sample.kind == zenoh.SampleKind.PUT))

    def stop(self) -> None:
        self.stopping = True
        self._post("stop", None)

    def _drop(self, key: str, why: str) -> None:
        self.dropped += 1
        self._log_some(self.dropped, f"dropped message #{self.dropped} on {key}: {why}")

    def _reject(self, key: str, why: str) -> None:
        self.rejected += 1
        self._log_some(self.rejected, f"refused state #{self.rejected} on {key}: {why}")

    def _log_some(self, count: int, line: str) -> None:
        """The first 20 of a kind, then every thousandth: a flood cannot fill the log."""
        if count <= 20 or count % 1000 == 0:
            print(f"agent {self.robot}: {line}", file=sys.stderr, flush=True)

    def _follow_neighbours(self) -> None:
        """Subscribe to exactly the state keys membership follows: the neighbours', and
        those of the candidates (ids next to ours whose tokens are not up to us)."""
        wanted = self.membership.followed()
        if self.bounds is None:
            # Before the first sensing we do not know if the edge is closed: listen to
            # the ring's neighbours too (robot 0's lower one is robot n-1), so that on a
            # ring their states of tick 0, sent as the run begins, are not lost to a
            # subscription made only when the sensing says so. States wait until then
            # (parked); on a chain those of a robot that is no neighbour are not kept.
            wanted = wanted | ({(self.robot - 1) % self.team, (self.robot + 1) % self.team}
                               - {self.robot})
        if wanted == self.neighbour_subs.keys():
            return
        for rid in set(self.neighbour_subs) - wanted:
            self.neighbour_subs.pop(rid).undeclare()
        for rid in wanted - set(self.neighbour_subs):
            self.neighbour_subs[rid] = self.session.declare_subscriber(
                self.keys.state(rid), self._on("state")
            )

    def _handle(self, kind: str, data: Any) -> None:
        if kind == "alive":
            rid, up = data
            self.membership.alive(rid, up)
            self._follow_neighbours()
            return
        key, payload = data
        try:
            if kind == "sense":
                msg = decode(Sense, payload)
                if msg.robot != self.robot:
                    raise DecodeError(f"sense for robot {msg.robot}")
                self.senses[msg.k] = msg
                self._prune(self.senses)
                if msg.k > self.newest_k:
                    self.newest_k = msg.k
                    first = self.bounds is None
                    if first:  # now states can be judged: every one parked so far is
                        if msg.closed:
                            self.closed = True
                            self.membership.close_ring()
                            self._take_contour()
                        self.bounds = self._bounds(msg)
                        self._follow_neighbours()
                    self._unpark(every=first)
                if msg.pose:  # the robot's pose came with its sensing
                    x, y, theta = msg.pose
                    self.poses[msg.k] = Pose(msg.t, msg.k, msg.robot, x, y, theta,
                                             source=msg.pose_source)
                    self._prune(self.poses)
            elif kind == "pose":
                pose = decode(Pose, payload)
                if pose.robot != self.robot:
                    raise DecodeError(f"pose for robot {pose.robot}")
                self.poses[pose.k] = pose
                self._prune(self.poses)
            elif kind == "info":
                self._info(key, decode(WorldInfo, payload))
            elif kind == "state":
                state = decode(AgentState, payload)
                if Keys.robot_of(key) != state.robot:
                    raise DecodeError(f"state of robot {state.robot} on {key}")
                self._judge(key, state)
        except DecodeError as exc:
            self._drop(key, str(exc))

    def _info(self, key: str, info: WorldInfo) -> None:
        """The world's WorldInfo: on a closed edge, its contour is our edge frame (the
        first one that fits our sensing's edge; an unlike one after it is refused)."""
        if not info.closed:
            return
        if self.contour is None:
            self.contour = list(info.contour)
            self._take_contour()
        elif info.contour != self.contour:
            self._reject(key, "a second world with another contour")

    def _take_contour(self) -> None:
        """Build the edge frame from the contour heard, once the sensing has said the
        edge is closed and how long it is; a contour that does not fit is dropped."""
        if (self.ring_edge is not None or self.contour is None or not self.senses
                or not self.closed):
            return
        sense = self.senses[max(self.senses)]
        c = self.contour
        try:
            edge = ClosedEdge(list(zip(c[0::2], c[1::2], strict=True)))
        except ValueError as exc:
            self.contour = None
            self._reject(self.keys.world_info(), f"a contour that is no closed edge: {exc}")
            return
        length = sense.edge_hi - sense.edge_lo
        if abs(edge.length - length) > 1e-6 * max(1.0, length):
            self.contour = None
            self._reject(self.keys.world_info(), f"a contour {edge.length:.6g} m long; our "
                         f"edge is {length:.6g} m")
            return
        self.ring_edge = edge

    def _judge(self, key: str, state: AgentState, unawaited: bool = False) -> None:
        """A neighbour's well-formed state: kept if plausible (agent.plausible), else
        counted, logged and dropped, as if it never came: the tick waits for the real one
        as for a late state (a refused copy must not let it act without the real one)."""
        if self.bounds is not None:  # before any sensing: no edge or clock to judge by
            why = plausible.state_problem(state, self.bounds, self.newest_k)
            if why is not None:
                self._reject(key, why)
                return
        if state.k > self.newest_k:
            # A state of a tick whose sensing we do not have yet waits here until we do
            # and is judged then, against its sender's previous state: a state sent early
            # cannot stand in for the real one when the tick comes. Nothing acts on a
            # neighbour's state of tick k before our own tick k+1. Every unlike copy of
            # a tick waits (a forgery may come before the real state or after it, and
            # neither may displace the other) and each is judged in turn.
            self._keep(self.parked, key, state)
            return
        lower, upper = self.membership.neighbours()
        side = "lower" if state.robot == lower else "upper" if state.robot == upper else None
        if side is not None:
            before = self.membership.latest(state.robot, state.k - 1)
            if (not unawaited and before is not None and before.k < state.k - 1
                    and state.k >= self.membership.last_k):
                self._keep(self.awaiting, key, state)
                return
            why = plausible.neighbour_problem(
                state, self.robot, side, self.claims, before, self.gains.min_segment_m,
                self.bounds.length if self.bounds is not None and self.closed else None)
            if why is not None:
                self._reject(key, why)
                return
            if self._contested(key, state, before):
                return
        if self.membership.heard(state.robot, state.k, state) and side is None:
            # a candidate's state: it is our neighbour now
            self.found += 1
            self._log_some(self.found, f"robot {state.robot}'s state of tick {state.k} came, "
                           "its token has not: it is live")
            self._follow_neighbours()
        # the state its next one waited for: that one can be judged by the law now
        for key_next, next_state in self.awaiting.pop((state.robot, state.k + 1), []):
            self._judge(key_next, next_state)

    def _keep(self, store: dict[tuple[int, int], list[tuple[str, AgentState]]], key: str,
              state: AgentState) -> None:
        """Keep ``state`` in ``store`` (``parked`` or ``awaiting``) to be judged later;
        a copy of one kept is dropped, and past the store's bounds the state is refused."""
        rk = (state.robot, state.k)
        held = store.get(rk, [])
        if any(state == other for _, other in held):
            return
        if len(held) >= COPIES_PARKED or (not held and len(store) >= PARKED_STATES):
            self._reject(key, f"too many states wait for tick {state.k}")
            return
        store.setdefault(rk, []).append((key, state))

    def _judge_awaiting(self, k: int) -> None:
        """Before deciding tick ``k``: judge the states of ticks before it still waiting
        for their sender's previous one, without it (it was lost, refused, or sent
        before we listened)."""
        for rk in sorted(rk for rk in self.awaiting if rk[1] < k):
            # (judging one can release the next of its sender, already popped then)
            for key, state in self.awaiting.pop(rk, []):
                self._judge(key, state, unawaited=True)

    def _contested(self, key: str, state: AgentState, before: AgentState | None) -> bool:
        """A second plausible state of a neighbour's tick, unlike the one kept: one of
        the two is a lie the rules cannot tell (a boundary not ours to check, say), and
        which came first is a matter of timing. The one that moves the sender's
        boundaries less from its state before is kept, the other counted and dropped;
        True if ``state`` is the one dropped."""
        kept = self.membership.latest(state.robot, state.k)
        if kept is None or kept.k != state.k or kept == state:
            return False
        if before is None:  # nothing to tell them by: the first stays
            self._reject(key, f"a second state of tick {state.k}, unlike the first")
            return True

        def step(s: AgentState) -> float:
            return abs(s.lo - before.lo) + abs(s.hi - before.hi)

        further = step(state) >= step(kept)
        self._reject(key, f"two unlike states of tick {state.k}; the one further from "
                     f"tick {before.k}'s boundaries dropped")
        return further

    def _unpark(self, every: bool = False) -> None:
        """Judge the states parked for ticks we now have sensing of (``every``: all of
        them, at the first Sense; those still ahead are parked again), in tick order."""
        due = sorted(rk for rk in self.parked if every or rk[1] <= self.newest_k)
        for rk in due:
            for key, state in self.parked.pop(rk):
                self._judge(key, state)

    def _bounds(self, sense: Sense) -> plausible.Bounds:
        p, g = self.patrol_cfg, self.gains
        edge = sense.edge_hi - sense.edge_lo
        return plausible.Bounds(
            sense.edge_lo, sense.edge_hi,
            depth_max=p.max_depth_m + p.margin_out_m + p.max_search_m,
            # a ring's depth map: a whole number of bins make the ring
            bin_m=ring_bins(edge, p.bin_m) if sense.closed else p.bin_m,
            max_passes=passes_for(edge, p.max_spacing_m, p.passes_per_sweep),
            # (the reach of a sender's bins is judged on a ring only)
            closed=sense.closed, reach_m=g.shared_reach_m,
            reach_fraction=g.shared_reach_fraction)

    def _neighbour_view(self, rid: int | None, k: int) -> Neighbour | None:
        """The neighbour's state of tick k-1 (or the latest before k if that is missing)."""
        s = self.membership.latest(rid, k - 1)
        if s is None:
            return None
        return Neighbour(s.robot, s.lo, s.hi, s.phase_des, s.workload, s.turns,
                         tuple(zip(s.end_bins, s.end_depths, strict=True)), s.cycle_s,
                         s.passes, s.need_below, s.need_above, s.span_below, s.span_above)

    def _prune(self, by_tick: dict[int, Any]) -> None:
        done = self.membership.last_k
        for old in [k for k in by_tick if k <= done or k < max(by_tick) - HISTORY]:
            del by_tick[old]

    def _done_k(self) -> int:
        """The last tick done: acted on, stood still on, or given up on for a fault."""
        return max(self.membership.last_k, self.halted_k)

    def _ready_tick(self) -> int | None:
        """The newest tick after the last one done with both its Sense and its Pose."""
        if self.closed and self.ring_edge is None:
            return None  # the contour has not come yet
        done = self._done_k()
        ready = [k for k in self.senses if k > done and k in self.poses]
        if not ready:
            return None
        k = max(ready)
        self.sense, self.pose = self.senses[k], self.poses[k]
        return k

    def learn_members(self, timeout_s: float = MEMBERS_TIMEOUT_S) -> None:
        """Ask who is alive now, before the first tick. The liveliness subscriber's
        history comes asynchronously and a Sense can come first: an agent restarted in
        a running team that acted on it would think itself alone and claim the whole
        edge for a tick. Later changes come through the subscriber as usual."""
        try:
            replies = self.session.liveliness().get(self.keys.alive("*"), timeout=timeout_s)
            for reply in replies:
                sample = reply.ok
                rid = None if sample is None else Keys.robot_of(str(sample.key_expr))
                if rid is not None:
                    self._handle("alive", (rid, True))
        except zenoh.ZError as exc:  # the subscriber will tell us in time
            print(f"agent {self.robot}: liveliness query failed: {exc}", file=sys.stderr)

    def run(self) -> None:
        inbox = self.inbox
        while not self.stopping:
            done = self._done_k()
            self.waiting = any(k > done for k in self.senses)
            if not inbox:
                deadline = self.membership.deadline
                # (a deadline with no tick to decide, as after a fault: nothing to wake for)
                timeout = (0.5 if deadline is None or not self.waiting
                           else max(0.0, deadline - time.monotonic()))
                try:
                    self.wake.get(timeout=timeout)
                except queue.Empty:
                    pass
            while inbox:  # everything that has arrived, before deciding
                kind, data = inbox.popleft()
                if kind == "stop":
                    return
                try:
                    self._handle(kind, data)
                except Exception as exc:  # noqa: BLE001 - a fault of ours: see _fault
                    self._fault(f"a {kind} message", exc)
            k = self._ready_tick()
            if k is None:
                continue
            try:
                self._decide(k)
            except RingGainsError:
                raise  # the configuration, not a fault: the agent refuses it (main)
            except Exception as exc:  # noqa: BLE001 - a fault of ours: see _fault
                self._fault(f"tick {k}", exc)
                self.halted_k = k
                self._stand_still(k)

    def _fault(self, what: str, exc: Exception) -> None:
        """An exception of our own code on something from the bus that the checks let
        through: it must not end the robot's controller. It is counted and logged (the
        first ones with their traceback, for the bug report); the message is dropped, or
        the tick given up on with a zero command."""
        self.faults += 1
        lines = (traceback.format_exception(exc) if self.faults <= 3
                 else traceback.format_exception_only(exc))
        self._log_some(self.faults, f"fault #{self.faults} on {what}, dropped: "
                       + "".join(lines).rstrip())

    def _decide(self, k: int) -> None:
        """Tick ``k``'s sensing and pose are in: judge what waited for it, ask membership,
        and act, stand still or wait."""
        self._judge_awaiting(k)
        decision = self.membership.decide(k, time.monotonic())
        self._follow_neighbours()  # one live by its states alone may have gone silent
        if decision is Decision.STAND_STILL:
            self._stand_still(k)  # joining a running team: claim once we hear them
        elif decision is Decision.ACT:
            if self.membership.timed_out:
                self.timeouts += 1
                what = f"a neighbour's state of tick {k - 1}" if k else "the whole team"
                self._log_some(self.timeouts, f"tick {k}: acted without {what}, after "
                               f"waiting {self.membership.waited_s:.2f} s "
                               f"(#{self.timeouts})")
            self._tick(k)
        # WAIT: a neighbour's state may still come; we wake by membership.deadline

    def _stand_still(self, k: int) -> None:
        """Tick k of an agent joining a running team before it has heard its neighbours
        (or one given up on for a fault): a zero command, so the world need not wait for
        us, and no state, so the neighbours keep their segments. Their states of tick k
        then reach us (our subscriptions are in place by now), and at k+1 we claim our
        share of them. Claiming sooner would take a neighbour not heard yet for the end
        of the chain and claim the edge up to its end."""
        sense = self.sense
        assert sense is not None
        self.pub_cmd.put(encode(Cmd(t=sense.t, k=k, robot=self.robot, v=0.0, omega=0.0)))

    def _tick(self, k: int) -> None:
        sense, pose = self.sense, self.pose
        assert sense is not None and pose is not None
        if self.controller is None:
            lo, hi = self.membership.first_segment(k, sense.edge_lo, sense.edge_hi)
            if self.ring_edge is not None:
                g = self.gains
                problems = check_gains(self.team, g.k_phi, g.k_s, self.max_depth_m, closed=True)
                if problems:
                    raise RingGainsError("; ".join(problems))
                self.controller = RingController(
                    self.robot, self.team, self.ring_edge, lo, hi, pose.x, pose.y,
                    self.gains, self.patrol_cfg, self.limits, self.max_depth_m)
            else:
                self.controller = Controller(
                    self.robot, lo, hi, sense.edge_lo, sense.edge_hi, pose.x,
                    self.gains, self.patrol_cfg, self.limits,
                )
        lower_id, upper_id = self.membership.neighbours()
        views = (sense.dt, pose.x, pose.y, pose.theta, sense.ice, sense.algae,
                 self._neighbour_view(lower_id, k), self._neighbour_view(upper_id, k),
                 lower_id is not None, upper_id is not None)
        if isinstance(self.controller, RingController):  # its neighbours round the ring
            out = self.controller.step(*views, ids=(lower_id, upper_id))
        else:
            out = self.controller.step(*views)
        me = self.controller.published
        assert me is not None
        state = AgentState(
            t=sense.t, k=k, robot=self.robot, lo=out.lo, hi=out.hi, phase=out.phase,
            phase_des=out.phase_des, workload=out.workload, depth_avg=out.depth_avg,
            direction=out.direction, lower=-1 if lower_id is None else lower_id,
            upper=-1 if upper_id is None else upper_id,
            edge_lo=sense.edge_lo, edge_hi=sense.edge_hi, dropped=self.dropped,
            rejected=self.rejected,
            turns=out.turns, end_bins=[b for b, _ in out.end_depths],
            end_depths=[d for _, d in out.end_depths],
            cycle_s=me.cycle_s, passes=me.passes, need_below=me.need_below,
            need_above=me.need_above, span_below=me.span_below, span_above=me.span_above,
            closed=self.closed,
        )
        # The state before the command: the world cannot step (and start tick k+1) until
        # every command is in, so each neighbour's state of tick k is always out before
        # anyone acts on k+1, however loaded the machine; the run stays deterministic.
        # (Command first was a few per cent faster, but under load a neighbour's state
        # could come after the neighbour timeout, and the run then depended on timing.)
        self.claims[k] = plausible.Claim(out.lo, out.hi, out.workload)
        for old in [kk for kk in self.claims if kk < k - HISTORY]:
            del self.claims[old]
        self.pub_state.put(encode(state))
        self.pub_cmd.put(encode(Cmd(t=sense.t, k=k, robot=self.robot, v=out.v, omega=out.omega)))
        self.ticks += 1

    def close(self) -> None:
        self.token.undeclare()


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    overrides = {
        "gains": {"k_s": args.k_s, "k_phi": args.k_phi, "cycle_s": args.cycle_s},
        "patrol": {"passes_per_sweep": args.passes, "sensor_latency_s": args.sensor_latency,
                   "sensor_band_m": args.sensor_band},
    }
    try:
        gains, patrol, limits = agent_config.load(args.config, overrides)
    except agent_config.ConfigError as exc:
        print(f"btrack agent: {exc}", file=sys.stderr)
        return 2
    if not 0 <= args.id < args.robots:
        print(f"btrack agent: --id {args.id} outside a team of {args.robots}", file=sys.stderr)
        return 2
    if patrol.sensor_latency_s or patrol.sensor_band_m:
        print(f"btrack agent {args.id}: ice and algae readings placed back for "
              f"{patrol.sensor_latency_s:g} s of latency and a {patrol.sensor_band_m:g} m "
              "dead band", file=sys.stderr, flush=True)
    problems = check_gains(args.robots, gains.k_phi, gains.k_s, args.max_depth)
    if problems:
        print("btrack agent: unstable gains: " + "; ".join(problems), file=sys.stderr)
        return 2
    if not 0.0 <= args.token_grace < math.inf:
        print(f"btrack agent: --token-grace {args.token_grace:g}: expected 0 or more "
              "wall seconds", file=sys.stderr)
        return 2
    opts = options_from_args(args)
    if opts.lease_s is None and not (opts.config_file or os.environ.get("ZENOH_CONFIG")):
        # a robot's neighbours must notice within a second that it froze
        opts = dataclasses.replace(opts, lease_s=DEFAULT_LEASE_S)
    with open_session(opts) as session:
        node = AgentNode(session, Keys(opts.ns), args.id, args.robots, gains, patrol, limits,
                         args.neighbour_timeout, args.max_depth, args.token_grace)
        for sig in (signal.SIGTERM, signal.SIGINT):
            signal.signal(sig, lambda *_: node.stop())
        try:
            node.learn_members()
            node.run()
        except RingGainsError as exc:
            print(f"btrack agent: unstable gains on the ring: {exc}", file=sys.stderr)
            return 2
        finally:
            node.close()
            print(json.dumps({"agent": args.id, "ticks": node.ticks, "dropped": node.dropped,
                              "rejected": node.rejected, "timeouts": node.timeouts,
                              "faults": node.faults}),
                  flush=True)
    return 0
