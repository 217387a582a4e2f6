"""What a neighbour may claim: plausibility rules for a well-formed ``AgentState``.

The codec refuses what is malformed (types, ranges, non-finite numbers); these rules
refuse what is well formed but cannot be true, so one forged or broken state cannot
push a robot off its segment, stall the lockstep or poison the workload for the rest of
a run (issue 19). Two layers, both pure:

- ``state_problem``: what any listener can check alone (an agent, the recorder): the
  tick within a window of the listener's own clock, the edge the listener knows, depths
  no patrol can measure, a workload that is not the depth times the segment.
- ``neighbour_problem``: what only the neighbour sharing a boundary can check, against
  its own recent states and the sender's previous one: the shared boundary where the
  workload law (eq. 4.3, ``shared_boundary``) can put it in one tick, never past the
  middle of the listener's own segment.

On a ring (a closed edge) the sender's arc and bins are in its own frame of s, which
differs from the listener's by whole turns (agent.ring): a wrap by whole turns is no
jump. Its bins must lie near its arc (there is no end of the edge to fall off), and the
shared boundary is judged in the listener's frame, the sender's values moved into it
by the whole turns their two views of that boundary tell (``frame_shift``).

The sweep count (``turns``) is not judged: it jumps, rightly, whenever a robot's lower
neighbour changes (it takes the new one's count), and that jump runs up the chain.

Each returns None for a plausible state, else the rule it breaks (for the count and the
log). A state refused is dropped as if it never came: the tick waits for the real one
as for a late state (so a refused copy cannot make it act without the real one).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from agent.partition import SegmentView, boundary_reach
from agent.ring import frame_shift
from wire.messages import AgentState

MAX_AHEAD_TICKS = 10  # a neighbour's state this many ticks past our newest sensing, at most
MAX_BEHIND_TICKS = 64  # and no older than this (nobody acts on it)
TOL_M = 1e-6  # boundaries: rounding between two robots evaluating the same law
NO_PASS_LIMIT = 1 << 30  # for a listener that does not know the patrol's spacing


def edge_bins(edge_lo: float, edge_hi: float, bin_m: float) -> int:
    """How many depth-map bins of ``bin_m`` the edge [edge_lo, edge_hi] has (0 to
    this - 1; a last partial bin counts)."""
    return math.ceil((edge_hi - edge_lo) / bin_m - 1e-9)


@dataclass(frozen=True)
class Bounds:
    """What the listener knows for sure: the edge (from its own sensing), the deepest
    depth a patrol can measure (its patrol's ``max_depth_m`` plus its margins), the bin
    of the depth maps and the most passes per sweep a team on this edge can need."""

    edge_lo: float
    edge_hi: float
    depth_max: float
    bin_m: float
    max_passes: int
    # A closed edge (a ring of length edge_hi - edge_lo): a sender's bins must lie within
    # ``reach_m`` (or ``reach_fraction`` of its arc, if more) of its arc, as the bins it
    # tells of do (agent.controller: ``shared_reach_m``, ``shared_reach_fraction``).
    closed: bool = False
    reach_m: float = 0.0
    reach_fraction: float = 0.0

    @property
    def bins(self) -> int:
        return edge_bins(self.edge_lo, self.edge_hi, self.bin_m)

    @property
    def length(self) -> float:
        return self.edge_hi - self.edge_lo


@dataclass(frozen=True)
class Claim:
    """A robot's own published segment and workload at one tick."""

    lo: float
    hi: float
    workload: float


def state_problem(s: AgentState, bounds: Bounds, newest_k: int | None,
                  ahead: int = MAX_AHEAD_TICKS, behind: int = MAX_BEHIND_TICKS) -> str | None:
    """The rules any listener checks; ``newest_k`` is the listener's newest tick (None if
    it has none yet: the window is not checked), ``ahead`` and ``behind`` the window
    (a listener whose clock comes on another link than the states, as the recorder's,
    needs a wide one: the bus orders messages per publisher only)."""
    if newest_k is not None:
        if s.k > newest_k + ahead:
            return f"tick {s.k} is more than {ahead} ahead of ours ({newest_k})"
        if s.k < newest_k - behind:
            return f"tick {s.k} is more than {behind} behind ours ({newest_k})"
    if abs(s.edge_lo - bounds.edge_lo) > TOL_M or abs(s.edge_hi - bounds.edge_hi) > TOL_M:
        return (f"edge [{s.edge_lo:g}, {s.edge_hi:g}] is not ours "
                f"[{bounds.edge_lo:g}, {bounds.edge_hi:g}]")
    if s.depth_avg > bounds.depth_max:
        return f"mean depth {s.depth_avg:g} m is deeper than any patrol ({bounds.depth_max:g} m)"
    if any(d > bounds.depth_max for d in s.end_depths):
        return f"a depth of its ends is deeper than any patrol ({bounds.depth_max:g} m)"
    if s.closed != bounds.closed:
        return "a closed edge's state on an open one" if s.closed else (
            "an open edge's state on a closed one")
    if bounds.closed:
        span = s.hi - s.lo
        reach = max(bounds.reach_m, bounds.reach_fraction * span) + bounds.bin_m
        if any(not s.lo - reach <= (b + 0.5) * bounds.bin_m <= s.hi + reach
               for b in s.end_bins):
            return (f"a bin of its ends is more than {reach:.3g} m from its arc "
                    f"[{s.lo:.6g}, {s.hi:.6g}]")
    elif any(not 0 <= b < bounds.bins for b in s.end_bins):
        return f"a bin of its ends is off the edge's {bounds.bins} bins"
    span = s.hi - s.lo
    if abs(s.workload - s.depth_avg * span) > 1e-6 * max(1.0, s.workload):
        return (f"workload {s.workload:g} m^2 is not its mean depth times its segment "
                f"({s.depth_avg * span:g} m^2)")
    if s.passes > bounds.max_passes:
        return f"{s.passes} passes per sweep; this edge needs at most {bounds.max_passes}"
    return None


def on_ring(s: AgentState, side: str, claim: Claim, length: float) -> AgentState:
    """A ring neighbour's state moved into the listener's frame by the whole turns that
    put the boundary the two share (its hi for a lower neighbour, its lo for an upper
    one) nearest the listener's view of it in ``claim``."""
    lower = side == "lower"
    shift = frame_shift(s.hi if lower else s.lo, claim.lo if lower else claim.hi, length)
    if shift == 0.0:
        return s
    return replace(s, lo=s.lo + shift, hi=s.hi + shift, edge_lo=s.edge_lo + shift,
                   edge_hi=s.edge_hi + shift)


def neighbour_problem(s: AgentState, me: int, side: str, mine: dict[int, Claim],
                      theirs_before: AgentState | None, min_segment_m: float,
                      ring_length: float | None = None) -> str | None:
    """The rules only a neighbour checks. ``me``: the listener's id; ``side``: "lower" if
    the sender is the listener's lower neighbour, "upper" if its upper one; ``mine``:
    the listener's own recent claims by tick; ``theirs_before``: the sender's latest
    state before ``s`` as heard, None if none.

    Where the sender names the listener on that side and its state of tick k-1 is here,
    the boundary they share must be where the law (``shared_boundary``) can put it from
    that state and one of the listener's recent ones (on the wall clock, or over a slow
    link, the sender may have acted on an older one of ours), or where it was (it had not
    heard us in time). Otherwise a sender may claim exactly the edge's end on the
    listener's side (what the law gives a robot that lost sight of the listener, after a
    freeze, and that it keeps until it hears the listener: the two then meet in the
    middle), and no other point past the middle of the listener's latest segment (a
    quarter further for a robot just joining, which split from a slightly older one of
    ours).

    On a ring (``ring_length``, the closed edge's length) both states of the sender are
    first moved into the listener's frame (``on_ring``), and there is no edge's end to
    claim."""
    ks = [k for k in mine if k <= s.k - 1]
    if not ks:
        return None
    if ring_length is not None:
        latest = mine[max(ks)]
        s = on_ring(s, side, latest, ring_length)
        if theirs_before is not None:
            theirs_before = on_ring(theirs_before, side, latest, ring_length)
    lower = side == "lower"
    shared = s.hi if lower else s.lo
    names_me = (s.upper if lower else s.lower) == me
    before = theirs_before
    if names_me and before is not None and before.k == s.k - 1:
        kept = before.hi if lower else before.lo
        if abs(shared - kept) <= TOL_M:
            return None  # it kept the boundary: it had not heard us in time
        theirs = SegmentView(before.lo, before.hi, before.workload)
        for k in sorted(ks):  # the reach from our latest claim is the one reported
            c = mine[k]
            ours = SegmentView(c.lo, c.hi, c.workload)
            low, high = (boundary_reach(theirs, ours, min_segment_m) if lower
                         else boundary_reach(ours, theirs, min_segment_m))
            if low - TOL_M <= shared <= high + TOL_M:
                return None
        return (f"the boundary it shares with us is at {shared:.6g} m; from its state of "
                f"tick {s.k - 1} and ours the law can put it only in [{low:.6g}, {high:.6g}] m")
    edge_end = s.edge_hi if lower else s.edge_lo
    if ring_length is None and abs(shared - edge_end) <= TOL_M:
        # the edge's end: the law's claim of a robot that saw nobody on our side (it lost
        # sight of us, after a freeze), kept until it hears us; the two then meet in the
        # middle. Refusing it left both claiming the whole edge, each refusing the other.
        return None
    c = mine[max(ks)]
    reach = 0.5 * (c.hi - c.lo) * (1.5 if names_me else 1.0)
    past = shared - (c.lo + reach) if lower else (c.hi - reach) - shared
    if past > TOL_M:
        return (f"its end {shared:.6g} m reaches {past:.3g} m further into our segment "
                f"[{c.lo:.6g}, {c.hi:.6g}] than one tick of the law can")
    return None
