"""What the team agrees on over neighbour-only messages: the patrol rate and the
number of passes per sweep.

Both are team quantities: every robot's phase must run at one rate, and every robot
must make the same number of passes per sweep so that their phases take the same
levels (eq. 3.1 scales each segment to pi). Neither can be fixed for one map: a
10 m segment needs more passes than a 0.5 m one, and a robot with 1.5 m legs needs
longer per pass than one with 0.3 m legs. So each robot says what its own segment
needs, the chain carries the largest need in each direction, and the lowest live
robot (the chain's root, which already sets the team's sweep count) decides; every
other robot takes its lower neighbour's decision, so the chain agrees exactly once
the decision has travelled down it (one tick per robot).

Chain maxima, not a consensus that averages: each robot publishes the largest need
among the robots below it and itself (``below``) and among those above it and
itself (``above``), each computed afresh every tick from its neighbour's value of the
previous tick. A need that leaves the team (its robot died, or its segment got
easier) is gone from the chain within one tick per robot, which a max-consensus on
a single value (``max(mine, theirs)``, fed back on itself) never forgets.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class ChainMax:
    """The largest value of the robots below a robot (it included) and above it."""

    below: float
    above: float


def chain_max(own: float, lower_below: float | None, upper_above: float | None) -> ChainMax:
    """This robot's chain maxima from its own value and its neighbours' of the last
    tick (None: no neighbour on that side, or not heard yet)."""
    below = own if lower_below is None else max(own, lower_below)
    above = own if upper_above is None else max(own, upper_above)
    return ChainMax(below, above)


def team_max(own: float, lower_below: float | None, upper_above: float | None) -> float:
    """The largest value over the whole chain, as this robot sees it."""
    return max(own, lower_below or own, upper_above or own)


def passes_for(longest_m: float, max_spacing_m: float, min_passes: int,
               current: int | None = None, hysteresis: float = 0.15) -> int:
    """Passes per sweep for a team whose longest segment is ``longest_m``: at least
    ``min_passes``, and enough that no segment's passes are further apart than
    ``max_spacing_m`` (so every point of the edge is within the robot's reach of a pass
    every sweep). A change is made only when the present number no longer fits, or
    fits with more than ``hysteresis`` to spare, so a boundary hovering near a
    threshold does not flip the team's grid from sweep to sweep."""
    if not (0 < longest_m < math.inf and 0 < max_spacing_m < math.inf) or min_passes < 1:
        raise ValueError("need a positive finite segment and spacing, and passes")
    need = max(min_passes, math.ceil(longest_m / max_spacing_m - 1e-9))
    if current is None or current < need:
        return need
    if current > need and longest_m / (current - 1) < (1.0 - hysteresis) * max_spacing_m:
        return need
    return current


def cycle_for(pass_need_s: float, passes: int, margin: float) -> float:
    """The team cycle (one round trip of every segment, 2 ``passes`` arcs) that gives
    the slowest robot ``margin`` times the time its hardest pass needs."""
    return 2.0 * passes * pass_need_s * margin


@dataclass
class TeamRate:
    """The root's cycle, following the team's need: up at once (a robot that cannot
    keep up holds the team back through the phase consensus, and the longer it lags
    the further behind it falls), down slowly, over about one cycle, so that a need
    that flickers (a depth measured once too deep) does not make the rate hunt."""

    cycle_s: float | None = None

    def update(self, target_s: float, dt: float) -> float:
        if not target_s > 0:
            raise ValueError("the target cycle must be positive")
        if self.cycle_s is None or target_s >= self.cycle_s:
            self.cycle_s = target_s
        else:
            self.cycle_s += (target_s - self.cycle_s) * min(1.0, dt / self.cycle_s)
        return self.cycle_s

