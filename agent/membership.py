"""Membership and joining: one agent's place in the chain, as a pure core.

The shell (``agent.process``) feeds it what it hears: liveliness tokens coming and
going (``alive``), its neighbours' states (``heard``) and, once its robot's sensing of
a tick is in, that tick with the wall time (``decide``). It answers who the neighbours
are (the nearest live lower and higher ids), whose states to listen to (``followed``),
whether to act on the tick, wait for a neighbour's state or stand still, and what
segment to claim first. It reads no clock: the time is an argument, so every race
between liveliness news and states can be played here in any order.

A robot is live to us when its token is, or, while its token is not, once a state of it
has come (issue 21). On a team's peer mesh a token does not always reach every peer:
with 50 agents on a loaded 2-core machine five to eight agents of a team went the whole
run without a neighbour's token (never seen, or seen once and gone while its robot ran
on), and in a bare mesh of 50 peers most missed some, while every peer's messages
reached every other (Zenoh's router forwards messages between peers with no direct
link, not their tokens). An agent that missed its lower neighbour's token took the next
one down for its neighbour, computed its boundary against that robot's segment, and the
neighbour it had missed refused every state it sent (further into its segment than one
tick of the law can move a boundary: rightly, the claim was made from the wrong chain)
and waited a second for each, so the whole lockstep crept at a tick a second. So each
agent also listens for the states of the ids nearest it in the gap to its neighbour on
each side (``candidates``), and takes one for live once a state of it comes.

On a ring (a closed edge, ``ring=True``) the ids wrap: the neighbours are the nearest
live ids below and above round the ring (agent.ring.ring_neighbours: robot 0's lower one
is the highest live id), both always exist while anyone else is live, the candidates
are counted round the ring too, and the first arcs are equal arcs of the ring from
s = 0; a robot joining a running ring claims from the middle of its lower neighbour's
arc to the middle of its upper one's (agent.ring.ring_join_arc). With one other robot
live it is the neighbour on both sides; alone, a robot has none (None, None) and owns
the whole contour (agent.ringcontrol). The chain's answers are unchanged.
"""

from __future__ import annotations

from enum import Enum
from typing import Generic, Protocol, TypeVar

from agent.controller import initial_segment
from agent.partition import SegmentView, join_segment
from agent.ring import initial_arc, ring_join_arc, ring_neighbours

HISTORY = 8  # neighbour states kept per neighbour, by tick
# Ids listened to on each side, nearest first, in the gap to the neighbour on that side
# (whose tokens are not up to us): the real neighbour is the nearest live id, so it is
# found unless as many robots next to us are gone as well.
CANDIDATES_PER_SIDE = 2
# A robot whose token went is taken back by its states only from this many ticks after
# our last one then: its last states may still be on their way (in lockstep at most one
# tick ahead of ours; on the wall clock as far ahead as agent.plausible lets a
# neighbour's state be, 10). A token can also go while its robot runs on, on a partial
# mesh (measured: 50 agents, robot 3's token went for robot 2 before tick 0 and never
# came back, its states did); then the robot is back after these ticks.
GONE_TICKS = 10
JOIN_WAIT_S = 1.0  # longest a joining agent stands still for its neighbours' states, wall s


class Segmented(Protocol):
    """What membership reads of a neighbour's state: its segment and workload."""

    @property
    def lo(self) -> float: ...

    @property
    def hi(self) -> float: ...

    @property
    def workload(self) -> float: ...


S = TypeVar("S", bound=Segmented)


class Stage(Enum):
    JOINING = "joining"  # no segment claimed yet: the team's start, or a (re)start mid-run
    MEMBER = "member"  # has claimed a segment and acts on every tick


class Decision(Enum):
    """What to do with a tick whose sensing is in."""

    WAIT = "wait"  # not yet: a neighbour's previous state may still come (see ``deadline``)
    STAND_STILL = "stand still"  # a zero command and no state: joining, neighbours unheard
    ACT = "act"  # step the controller and publish its state


# Stage after each decision; a member never stands still (it holds a segment).
TRANSITIONS: dict[tuple[Stage, Decision], Stage] = {
    (Stage.JOINING, Decision.WAIT): Stage.JOINING,
    (Stage.JOINING, Decision.STAND_STILL): Stage.JOINING,
    (Stage.JOINING, Decision.ACT): Stage.MEMBER,
    (Stage.MEMBER, Decision.WAIT): Stage.MEMBER,
    (Stage.MEMBER, Decision.ACT): Stage.MEMBER,
}


class Membership(Generic[S]):
    """Robot ``robot`` of a team started as ``team`` robots: its live peers, its
    neighbours' recent states, and the decision for each tick.

    ``neighbour_timeout_s`` is how long (wall s) a tick waits for a live neighbour's
    previous state before acting without it; ``join_wait_s`` how long an agent joining
    a running team stands still for its neighbours before it claims without them.
    Ids outside ``team`` count as live peers like any other (a robot added to a
    running team has an id past the size the others were started with)."""

    def __init__(self, robot: int, team: int, neighbour_timeout_s: float = 1.0,
                 join_wait_s: float = JOIN_WAIT_S, ring: bool = False,
                 token_grace_s: float = 0.0):
        if not 0 <= robot < team:
            raise ValueError(f"robot id {robot} outside a team of {team}")
        self.robot = robot
        self.team = team
        self.ring = ring
        self.neighbour_timeout_s = neighbour_timeout_s
        self.join_wait_s = join_wait_s
        if not token_grace_s >= 0.0:
            raise ValueError(f"token grace {token_grace_s} s is not 0 or more")
        self.token_grace_s = token_grace_s
        # Neighbours whose token went while we held them (``token_grace_s``): live to us
        # by their states (in ``_proven``) until a tick waits that long for one in vain.
        self._held: set[int] = set()
        self._live: set[int] = set()
        # Live to us by their states alone, their tokens not up (see the module's doc);
        # and, of a robot seen to go or waited for in vain, the last tick whose state
        # proves nothing (one still on its way, sent before it went).
        self._proven: set[int] = set()
        self._silent: dict[int, int] = {}
        self._states: dict[int, dict[int, S]] = {}  # by neighbour, by tick
        self._followed_at: dict[int, int] = {}  # by neighbour: our last tick when it became one
        self._mute: set[int] = set()  # neighbours waited for in vain, none of whose states came
        self._stage = Stage.JOINING
        self._last_k = -1  # the last tick acted on or stood still on
        self._deadline: float | None = None  # until when a tick waits (see ``decide``)
        self._wait_began: float | None = None  # when it began to wait
        self._waited_s = 0.0  # how long the last tick acted on without a state waited
        self._timed_out = False  # the last decision acted without a neighbour's state
        self._join_deadline: float | None = None  # until when a joining agent stands still
        self._refollow()  # the candidates, before any token news

    # -- what it is told --------------------------------------------------------------

    def alive(self, robot: int, up: bool) -> None:
        """Robot ``robot``'s liveliness token appeared (``up``) or vanished. A frozen
        agent's vanishes when its lease runs out and appears again when it thaws. When
        this changes the neighbours, a new neighbour's history starts empty and one that
        is no longer a neighbour is forgotten."""
        if robot == self.robot:
            return
        was_held = robot in self._held
        self._held.discard(robot)
        if up:
            self._live.add(robot)
            self._silent.pop(robot, None)
            if was_held:  # back through another router: a state of the gap may be lost
                self._followed_at[robot] = self._last_k
        elif (self.token_grace_s > 0 and robot in self.neighbours()
              and self._states.get(robot)):
            # held: a neighbour we hear from stays one, its history kept, while its
            # states come (a router that died took its clients' tokens with it, and they
            # come back through another); dropped once a tick has waited
            # ``token_grace_s`` for one in vain (``decide``). As for a new neighbour,
            # the next tick does not wait for it: its state of our last tick may have
            # gone out on the link that broke (and every robot waiting for a lost state
            # stalled the lockstep for the whole neighbour timeout).
            self._live.discard(robot)
            self._proven.add(robot)
            self._held.add(robot)
            self._followed_at[robot] = self._last_k
            return
        else:
            self._live.discard(robot)
            self._silent[robot] = self._last_k + GONE_TICKS
        self._proven.discard(robot)
        self._refollow()

    def close_ring(self) -> None:
        """The edge turned out closed (the first sensing says so): the team is a ring.
        Only before the first tick, while nothing has been decided on the chain's rules."""
        if self._last_k >= 0:
            raise ValueError("a team becomes a ring only before its first tick")
        if not self.ring:
            self.ring = True
            self._refollow()

    def _refollow(self) -> None:
        """After the live set changed: a robot that stops being a neighbour is forgotten
        (its history starts empty if it comes back); a new neighbour is followed from our
        last tick, with the state that made it one if it was a candidate."""
        wanted = {r for r in self.neighbours() if r is not None}
        for rid in set(self._followed_at) - wanted:
            del self._followed_at[rid]
            del self._states[rid]
            self._mute.discard(rid)
            # live to us by its states alone, which we no longer follow (a nearer robot
            # came between): no longer live to us, until its token or a state says so
            self._proven.discard(rid)
            self._held.discard(rid)
        followed = wanted | self.candidates()
        for rid in set(self._states) - followed:
            del self._states[rid]
        for rid in followed - set(self._states):
            self._states[rid] = {}
        for rid in wanted - set(self._followed_at):
            self._followed_at[rid] = self._last_k

    def heard(self, robot: int, k: int, state: S) -> bool:
        """Neighbour ``robot``'s state of its tick ``k``; whether it was kept. A state of a
        robot that is not a neighbour (one sent before it stopped being one) is not; one
        of a candidate makes it live to us and a neighbour, unless it may have been sent
        before its robot went (``GONE_TICKS``) or is of a tick waited for in vain. States
        more than ``HISTORY`` ticks before our own last tick are forgotten (not before the
        newest state heard: one forged for a far tick must not push the real ones out)."""
        hist = self._states.get(robot)
        if hist is None:
            return False
        if robot not in self._followed_at:  # a candidate
            if k <= self._silent.get(robot, -1):
                return False
            self._proven.add(robot)
            self._silent.pop(robot, None)
            self._refollow()
            hist = self._states[robot]
        hist[k] = state
        self._mute.discard(robot)
        ref = self._last_k if self._last_k >= 0 else k
        for old in [kk for kk in hist if kk < ref - HISTORY]:
            del hist[old]
        return True

    def decide(self, k: int, now: float) -> Decision:
        """Tick ``k``'s sensing is in (a tick after the last one done) at wall time
        ``now``: act on it, wait for a neighbour's state, or stand still. Acting or
        standing still makes ``k`` the last tick done.

        A joining agent past tick 0 stands still while ``must_stand_still``. Otherwise a
        tick acts once its neighbours are heard (``neighbours_heard``; at tick 0
        ``team_heard``), or once it has waited ``neighbour_timeout_s`` since it began to
        wait (a wait that lasts over ticks, as with hardware, where tick k+1's sensing
        often comes before tick k's pose, keeps its deadline)."""
        if k <= self._last_k:
            raise ValueError(f"tick {k} is not after the last tick done, {self._last_k}")
        self._timed_out = False
        if self._stage is Stage.JOINING and k > 0 and self.must_stand_still(k, now):
            return self._enter(Decision.STAND_STILL, k)
        heard = self.neighbours_heard(k) if k > 0 else self.team_heard()
        if not heard:
            if self._wait_began is None:
                self._wait_began = now
            # waiting for held neighbours alone, their grace (they may have been held
            # since the wait began: a token's news can come after the tick)
            held = k > 0 and self._missing(self._need(k)) <= self._held
            self._deadline = self._wait_began + (
                min(self.token_grace_s, self.neighbour_timeout_s) if held
                else self.neighbour_timeout_s)
            if now < self._deadline:
                return self._enter(Decision.WAIT, k)
            self._timed_out = True
            self._waited_s = now - self._wait_began
            # waited in vain: a neighbour that never sent a state is not waited for again
            # until it does (a stray token, or a process up but not acting); one live to
            # us by its states alone is live no longer (it has no token to go with it)
            self._mute |= {rid for rid in self.neighbours()
                           if rid is not None and not self._states[rid]}
            if k > 0:
                self._drop_silent(self._need(k))
        return self._enter(Decision.ACT, k)

    def _drop_silent(self, need: int) -> None:
        silent = {rid for rid in self.neighbours() if rid in self._proven
                  and max(self._states[rid], default=-1) < need}
        for rid in silent:
            self._proven.discard(rid)
            self._held.discard(rid)
            self._silent[rid] = need
        if silent:
            self._refollow()

    def _enter(self, decision: Decision, k: int) -> Decision:
        self._stage = TRANSITIONS[(self._stage, decision)]
        if decision is not Decision.WAIT:
            self._last_k = k
        if decision is Decision.ACT:
            self._deadline = self._wait_began = None
        return decision

    # -- what it answers --------------------------------------------------------------

    @property
    def stage(self) -> Stage:
        return self._stage

    @property
    def last_k(self) -> int:
        """The last tick acted on or stood still on; -1 before the first."""
        return self._last_k

    @property
    def mute(self) -> frozenset[int]:
        """Live neighbours waited for in vain that have never sent a state: not waited
        for again until one comes."""
        return frozenset(self._mute)

    @property
    def live(self) -> frozenset[int]:
        """The other robots whose liveliness tokens are up."""
        return frozenset(self._live)

    @property
    def held(self) -> frozenset[int]:
        """Neighbours whose token went, held while their states come (``token_grace_s``)."""
        return frozenset(self._held)

    @property
    def proven(self) -> frozenset[int]:
        """The other robots live to us by their states alone (their tokens not up)."""
        return frozenset(self._proven)

    @property
    def timed_out(self) -> bool:
        """Whether the last decision acted without a neighbour's state, its wait for it
        over (``neighbour_timeout_s``): what a lockstep run does then depends on timing."""
        return self._timed_out

    @property
    def waited_s(self) -> float:
        """How long (wall s) the last tick acted on without a neighbour's state waited."""
        return self._waited_s

    @property
    def deadline(self) -> float | None:
        """The wall time at which a waiting tick acts without its neighbours' states
        (the shell wakes then to ask again); None while no tick waits."""
        return self._deadline

    @property
    def join_deadline(self) -> float | None:
        """The wall time at which a joining agent stops standing still for its
        neighbours; None until it first stood still."""
        return self._join_deadline

    def neighbours(self) -> tuple[int | None, int | None]:
        """The nearest live lower and higher ids (None at an end of the chain), live by
        token or by its states (``proven``)."""
        live = self._live | self._proven
        if self.ring:
            if not live - {self.robot}:
                return None, None
            return ring_neighbours(self.robot, sorted(live | {self.robot}))
        lower = max((r for r in live if r < self.robot), default=None)
        upper = min((r for r in live if r > self.robot), default=None)
        return lower, upper

    def candidates(self) -> frozenset[int]:
        """Ids whose states we listen for though they are not neighbours: on each side the
        ``CANDIDATES_PER_SIDE`` nearest ids between us and the neighbour there (the end
        of the team as started, without one); their tokens are not up to us."""
        lower, upper = self.neighbours()
        if self.ring:  # round the ring, up to the neighbour on each side
            # (a ring's order is by id: one past the team, which joined, sits between
            # the highest and robot 0)
            n = max(self.team, *(r + 1 for r in self._live | self._proven | {self.robot}))
            below = [(self.robot - j) % n for j in range(1, n)]
            above = [(self.robot + j) % n for j in range(1, n)]
        else:
            below = list(range(self.robot - 1, -1 if lower is None else lower, -1))
            above = list(range(self.robot + 1, self.team if upper is None else upper))
        out: set[int] = set()
        for ids, stop in ((below, lower), (above, upper)):
            gap = ids if stop is None or stop not in ids else ids[:ids.index(stop)]
            out.update(gap[:CANDIDATES_PER_SIDE])
        return frozenset(out)

    def followed(self) -> frozenset[int]:
        """Whose states to listen to: the neighbours and the candidates."""
        return frozenset(r for r in self.neighbours() if r is not None) | self.candidates()

    def latest(self, robot: int | None, newest_k: int) -> S | None:
        """Neighbour ``robot``'s latest state of tick ``newest_k`` or before, None if none."""
        hist = {} if robot is None else self._states.get(robot, {})
        ks = [kk for kk in hist if kk <= newest_k]
        return hist[max(ks)] if ks else None

    def latest_segment(self, robot: int | None, k: int) -> SegmentView | None:
        """A neighbour's latest state of tick k or before, as a segment: what an agent
        joining a running team claims a share of. Its state of tick k itself counts:
        under load a quicker neighbour's state of the tick being decided can be the
        first one heard of it."""
        s = self.latest(robot, k)
        return None if s is None else SegmentView(s.lo, s.hi, s.workload)

    def first_segment(self, k: int, edge_lo: float, edge_hi: float) -> tuple[float, float]:
        """The segment to claim on acting first, at tick ``k``: equal initial segments
        when the team starts together (tick 0, or no neighbour heard); otherwise a share
        of the live neighbours' latest segments (``join_segment``; round a ring
        ``ring_join_arc``), never past a live neighbour not heard yet."""
        lower_id, upper_id = self.neighbours()
        views = [self.latest_segment(rid, k) for rid in (lower_id, upper_id)]
        if self.ring and (k == 0 or all(v is None for v in views)):
            lo, hi = initial_arc(self.robot, self.team, edge_hi - edge_lo)
            return edge_lo + lo, edge_lo + hi
        if self.ring:
            return ring_join_arc(views[0], views[1], edge_hi - edge_lo,
                                 same=lower_id == upper_id)
        if k == 0 or all(v is None for v in views):
            return initial_segment(self.robot, self.team, edge_lo, edge_hi)
        return join_segment(views[0], views[1], edge_lo, edge_hi,
                            lower_unheard=lower_id is not None and views[0] is None,
                            upper_unheard=upper_id is not None and views[1] is None)

    # -- guards -----------------------------------------------------------------------

    def must_stand_still(self, k: int, now: float) -> bool:
        """Whether a joining agent stands still rather than claim a segment at tick k of
        a running team: it knows of no other live agent yet (the liveliness history of a
        session that has just linked up can come after its first sensing: acting then,
        a restarted agent would think itself alone and claim the whole edge), or some
        live neighbour's state (of tick k or before) is not here yet; and it has stood
        still for less than ``join_wait_s`` (a team starting together on the wall clock
        has nobody publishing yet; an agent really alone claims the edge after it).
        The wait begins the first time this is asked with something missing."""
        heard = all(rid is None or self.latest(rid, k) is not None
                    for rid in self.neighbours())
        if (self._live or self._proven) and heard:
            return False
        if self._join_deadline is None:
            self._join_deadline = now + self.join_wait_s
        return now < self._join_deadline

    def neighbours_heard(self, k: int) -> bool:
        """Whether every neighbour's state of tick k-1 is here; on the wall clock, where
        ticks can be skipped, of our own previous tick if we skipped k-1 (in lockstep
        that is k-1 itself), or any later one. A neighbour we began to hear only after
        that tick (one that just became our neighbour) may have published it before we
        listened: it is not waited for, and this tick acts on what we have (the lockstep
        must not stall at every membership change). An agent joining a running team
        waits for its neighbours' states of k-1 or later: it claims a share of them."""
        return not self._missing(self._need(k))

    def _missing(self, need: int) -> set[int]:
        """The neighbours waited for whose states of tick ``need`` or later are not here."""
        return {rid for rid in self.neighbours() if rid is not None
                and self._followed_at[rid] < need and rid not in self._mute
                and max(self._states[rid], default=-1) < need}

    def _need(self, k: int) -> int:
        """The tick of the neighbours' states that tick ``k`` waits for."""
        return k - 1 if self._last_k < 0 else min(k - 1, self._last_k)

    def team_heard(self) -> bool:
        """At tick 0 (a team starting together): whether the neighbours this robot starts
        with are alive to us, so that it follows them from its first tick. The world
        starts once it sees every token; each agent may see its neighbours' a little
        later, and one that had not would treat them as newcomers it need not wait for,
        and the run would depend on timing."""
        if self.ring:
            expected = {(self.robot - 1) % self.team, (self.robot + 1) % self.team} - {
                self.robot}
        else:
            expected = {r for r in (self.robot - 1, self.robot + 1) if 0 <= r < self.team}
        return expected <= self._live | self._proven
