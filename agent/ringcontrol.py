"""One robot's control law on a closed edge: the chain's controller (agent.controller)
run in the edge's frame, on a ring of neighbours.

The patrol state machine, the phase and workload laws and the depth map are the
chain's, unchanged: they are given the robot's pose in edge coordinates (s along the
contour in the robot's own frame, d across it, positive into the ice, and the heading
from the local tangent; agent.edgeframe), so a leg "along +y" is a leg along the local
normal, and the curvature they command comes back to the world through the edge's
curvature (``ClosedEdge.world_omega``): a leg is a straight line along the normal, an
arc bends with the edge. What the ring changes is who is a neighbour and in what frame
their values are (agent.ring): both neighbours always exist, their arcs and depth bins
are moved into this robot's frame by whole turns, the shared boundary is computed in
the lower robot's frame so the two agree exactly, and the team's agreement runs on the
ring cut between its highest id and its lowest.
"""

from __future__ import annotations

from dataclasses import replace

from agent.controller import (
    Controller,
    Gains,
    Neighbour,
    Output,
    RobotLimits,
    wheel_limited,
)
from agent.edgeframe import ClosedEdge
from agent.partition import SegmentView
from agent.patrol import PatrolConfig
from agent.ring import chain_sides, frame_shift, ring_shared_boundary
from agent.stability import check_gains


class RingController(Controller):
    """The control core of robot ``robot`` of a ring of ``team`` on ``edge``: ``lo``,
    ``hi`` its first arc (hi - lo at most the edge's length, lo in any whole turn);
    ``x``, ``y`` its world position at the start."""

    def __init__(
        self,
        robot: int,
        team: int,
        edge: ClosedEdge,
        lo: float,
        hi: float,
        x: float,
        y: float,
        gains: Gains | None = None,
        patrol: PatrolConfig | None = None,
        limits: RobotLimits | None = None,
        max_depth_m: float = 2.0,
    ) -> None:
        gains = gains or Gains()
        problems = check_gains(team, gains.k_phi, gains.k_s, max_depth_m, closed=True)
        if problems:
            raise ValueError("; ".join(problems))
        if team < 2 or not 0 <= robot < team:
            raise ValueError(f"robot {robot} of a ring of {team}: a ring needs two or more")
        self.frame = edge
        self.team = team
        self.length = edge.length
        s, _ = edge.project(x, y)
        self.s_hint = s
        self.edge_coordinates = (s, -1.0, 0.0)  # the last pose in the frame: s, d, psi
        # a neighbour's depths moved into this frame, kept while it publishes the same
        self._moved: dict[int, tuple[object, int, tuple[tuple[int, float], ...]]] = {}
        # the ids of the neighbours on each side, from membership (``step``'s ``ids``);
        # (i -+ 1) mod n until told otherwise, None on both sides for a robot alone
        self.neighbour_ids: tuple[int | None, int | None] = (
            (robot - 1) % team, (robot + 1) % team)
        super().__init__(robot, lo, hi, lo, hi, self._unwrapped(s, lo, hi), gains, patrol,
                         limits, ring_length=edge.length)

    def _unwrapped(self, s: float, lo: float, hi: float) -> float:
        """s in this robot's frame: the whole turn that puts it nearest its arc's middle."""
        return s + frame_shift(s, 0.5 * (lo + hi), self.length)

    # the ring's neighbours ------------------------------------------------------------
    def _shift_of(self, nb: Neighbour) -> float:
        """The whole turns that put neighbour ``nb``'s values in this robot's frame, from
        the boundary the two share (with two robots, the nearer of its two)."""
        lower_id, upper_id = self.neighbour_ids
        me_lo, me_hi = self.lo, self.hi
        if nb.robot == lower_id and nb.robot == upper_id:  # a ring of two
            by_lo = frame_shift(nb.hi, me_lo, self.length)
            by_hi = frame_shift(nb.lo, me_hi, self.length)
            return by_lo if abs(nb.hi + by_lo - me_lo) <= abs(nb.lo + by_hi - me_hi) else by_hi
        if nb.robot == lower_id:
            return frame_shift(nb.hi, me_lo, self.length)
        return frame_shift(nb.lo, me_hi, self.length)

    def _learn(self, nb: Neighbour) -> None:
        turns = round(self._shift_of(nb) / self.length)
        if turns == 0:  # the same tuple as the last tick's: the depth map knows it
            self.depth_map.learn(nb.depths)
            return
        cached = self._moved.get(nb.robot)
        if cached is None or cached[0] is not nb.depths or cached[1] != turns:
            bins = round(self.length / self.depth_map.bin_m)
            cached = (nb.depths, turns, tuple((b + turns * bins, d) for b, d in nb.depths))
            self._moved[nb.robot] = cached
        self.depth_map.learn(cached[2])

    def _chain_sides(self, lower: Neighbour | None, upper: Neighbour | None,
                     has_lower: bool, has_upper: bool) -> tuple[bool, bool]:
        lower_id = lower.robot if lower is not None else self.neighbour_ids[0]
        upper_id = upper.robot if upper is not None else self.neighbour_ids[1]
        if lower_id is None or upper_id is None:  # alone: no chain to agree on
            return False, False
        below, above = chain_sides(self.robot, lower_id, upper_id)
        return has_lower and below, has_upper and above

    def _update_boundaries(self, lower: Neighbour | None, upper: Neighbour | None,
                           has_lower: bool, has_upper: bool) -> None:
        """eq. 4.3 on both ends, each in the lower robot's frame (agent.ring). On a ring
        there are no ends of the edge: a side not heard yet keeps its boundary, and a
        robot with no neighbour on either side (alone on the ring) owns the whole contour
        from its lo."""
        g, me = self.gains, self.published
        if not has_lower and not has_upper:
            self.hi = self.lo + self.length
            return
        if me is None:
            return
        mine = SegmentView(me.lo, me.hi, me.workload)
        if has_lower and lower is not None:
            shift = frame_shift(me.lo, lower.hi, self.length)
            below = SegmentView(lower.lo, lower.hi, lower.workload)
            moved = SegmentView(me.lo + shift, me.hi + shift, me.workload)
            self.lo = ring_shared_boundary(below, moved, self.length, g.k_s,
                                           g.min_segment_m) - shift
        if has_upper and upper is not None:
            self.hi = ring_shared_boundary(
                mine, SegmentView(upper.lo, upper.hi, upper.workload), self.length, g.k_s,
                g.min_segment_m)
        if self.hi - self.lo < 1e-6:
            mid = 0.5 * (self.lo + self.hi)
            self.lo, self.hi = mid - 0.5e-6, mid + 0.5e-6

    # the edge's frame -----------------------------------------------------------------
    def edge_pose(self, x: float, y: float, theta: float) -> tuple[float, float, float]:
        """The world pose in this robot's edge frame: (s unwrapped, d, psi)."""
        s, d, psi = self.frame.to_edge(x, y, theta, self.s_hint)
        self.s_hint = s
        self.edge_coordinates = (self._unwrapped(s, self.lo, self.hi), d, psi)
        return self.edge_coordinates

    def step(
        self,
        dt: float,
        x: float,
        y: float,
        theta: float,
        ice: bool,
        algae: bool,
        lower: Neighbour | None,
        upper: Neighbour | None,
        has_lower: bool = True,
        has_upper: bool = True,
        ids: tuple[int | None, int | None] | None = None,
    ) -> Output:
        """One control tick from the robot's world pose; the command is the world's.
        ``ids``: the neighbours' ids on each side from membership (the nearest live ids
        round the ring; one robot on both sides in a ring of two; None, None alone);
        without it, those the robot was told last."""
        if ids is not None:
            self.neighbour_ids = ids
        s, d, psi = self.edge_pose(x, y, theta)
        out = super().step(dt, s, d, psi, ice, algae, lower, upper, has_lower, has_upper)
        omega = self.frame.world_omega(out.v, out.omega, s, d, psi)
        v, omega = wheel_limited(out.v, omega, self.limits)
        return replace(out, v=v, omega=omega)
