"""Phase along the patrol cycle: eq. 3.1 (corrected), wrapping, the desired-phase
update with feedback linearisation and chain consensus (eq. 4.5-4.8) and the speed
along the patrol (eq. 4.10 made to step one pass at a time)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # the array twins import numpy when called: an agent never needs it
    import numpy as np

TWO_PI = 2.0 * math.pi


def wrap_pi(angle: float) -> float:
    """Wrap an angle or phase difference to (-pi, pi]."""
    wrapped = math.fmod(angle + math.pi, TWO_PI)
    if wrapped <= 0.0:
        wrapped += TWO_PI
    return wrapped - math.pi


def wrap_2pi(angle: float) -> float:
    """Wrap a phase to [0, 2 pi)."""
    wrapped = math.fmod(angle, TWO_PI)
    if wrapped < 0.0:
        wrapped += TWO_PI
    return 0.0 if wrapped >= TWO_PI else wrapped


def position_to_phase(s_rob: float, lo: float, hi: float, direction: int) -> float:
    """Phase of a robot at ``s_rob`` on its segment [lo, hi], thesis eq. 3.1.

    The thesis's case condition ``s_i > 0`` is a typo for the direction of travel:
    going towards ``hi`` the phase runs 0 -> pi, coming back it runs pi -> 2 pi.
    """
    length = hi - lo
    if length <= 0.0:
        raise ValueError(f"empty segment [{lo}, {hi}]")
    s = min(max(s_rob, lo), hi)
    if direction > 0:
        return wrap_2pi(math.pi * (s - lo) / length)
    return wrap_2pi(math.pi * (hi - s) / length + math.pi)


def wrap_pi_array(angle: np.ndarray | float) -> np.ndarray:
    """``wrap_pi`` over an array (the report's and the localizer's): (-pi, pi]."""
    import numpy as np

    a = np.asarray(angle, dtype=float)
    return a - TWO_PI * np.ceil((a - math.pi) / TWO_PI)


def wrap_2pi_array(angle: np.ndarray | float) -> np.ndarray:
    """``wrap_2pi`` over an array: [0, 2 pi)."""
    import numpy as np

    a = np.mod(np.asarray(angle, dtype=float), TWO_PI)
    return np.where(a >= TWO_PI, 0.0, a)


def position_to_phase_array(
    x: np.ndarray | float,
    lo: np.ndarray | float,
    hi: np.ndarray | float,
    direction: np.ndarray | float,
) -> np.ndarray:
    """``position_to_phase`` (eq. 3.1) over arrays, for the report: x clipped into
    [lo, hi], towards hi while direction >= 0, result in [0, 2 pi)."""
    import numpy as np

    x, lo, hi, direction = (np.asarray(v, dtype=float) for v in (x, lo, hi, direction))
    width = hi - lo
    xc = np.clip(x, lo, hi)
    towards_hi = math.pi * (xc - lo) / width
    towards_lo = math.pi * (hi - xc) / width + math.pi
    return wrap_2pi_array(np.where(direction >= 0, towards_hi, towards_lo))


def phase_to_position(phase: float, lo: float, hi: float) -> tuple[float, int]:
    """Inverse of eq. 3.1: the position and direction of travel at ``phase``."""
    phase = wrap_2pi(phase)
    length = hi - lo
    if phase < math.pi:
        return lo + length * phase / math.pi, 1
    return hi - length * (phase - math.pi) / math.pi, -1


def boundary_phase_shift(
    s_rob: float, direction: int, old: tuple[float, float], new: tuple[float, float]
) -> float:
    """delta phi_s, thesis eq. 4.8: the jump in a robot's phase that a move of its
    boundaries causes while the robot itself stays at ``s_rob``."""
    return wrap_pi(
        position_to_phase(s_rob, new[0], new[1], direction)
        - position_to_phase(s_rob, old[0], old[1], direction)
    )


def consensus_term(
    phase_des: float, lower_phase_des: float | None, upper_phase_des: float | None, k_phi: float
) -> float:
    """K_phi e_phi,i - K_phi e_phi,i-1 of eq. 4.7, with e_phi,i = wrap(phi_{i+1} - phi_i).
    A missing neighbour (a chain end) contributes nothing."""
    term = 0.0
    if upper_phase_des is not None:
        term += k_phi * wrap_pi(upper_phase_des - phase_des)
    if lower_phase_des is not None:
        term -= k_phi * wrap_pi(phase_des - lower_phase_des)
    return term


def desired_phase_step(
    phase_des: float,
    phase_rate: float,
    dt: float,
    shift: float,
    consensus: float,
) -> float:
    """phi_des at the next step, thesis eq. 4.5 with the input of eq. 4.7.

    A boundary move re-expresses the phase by ``shift`` (eq. 4.8); the input cancels
    it (feedback linearisation), so the desired phase runs on at ``phase_rate`` and
    is pulled only by the consensus term.
    """
    natural = phase_des + shift
    control = phase_rate * dt - shift + consensus
    return wrap_2pi(natural + control)


def arc_may_begin(phase_des: float, level_from: float, level_to: float,
                  lead: float = 0.0) -> bool:
    """Whether the arc from the pass at phase ``level_from`` to the next (``level_to``)
    may begin: once the desired phase is ``lead`` short of the middle of the step, so
    that the robot's phase crosses the middle of the step (half way through the arc,
    ``lead`` being half the arc's duration in phase) when the team's desired phase does.
    Every robot's phase is then one staircase, stepping at the same moments whatever
    its legs and its arcs."""
    middle = level_from + 0.5 * wrap_pi(level_to - level_from)
    return wrap_pi(phase_des - (middle - lead)) >= 0.0


# The share of ``v_max`` the fast parts of a leg are reckoned at when the time to spare
# for measuring is worked out: a leg is never planned at full speed to the last metre.
FAST_SHARE = 0.8


def leg_speed(time_left_s: float, fast_m: float, slow_m: float, measuring: bool,
              v_max: float, v_measure: float, v_floor: float, v_fine: float = 0.0) -> float:
    """Forward speed on a straight leg, eq. 4.10 taken one pass at a time: paced to
    reach the leg's end (``fast_m`` to go at this speed, ``slow_m`` more at the
    measuring speed) when the next arc is due, ``time_left_s`` from now, so a robot with
    shallow legs drives them slowly instead of waiting at their ends; as fast as it may
    once late. Never slower than ``v_floor`` (the arc waits for the team instead), and
    at most ``v_measure`` while ``measuring``.

    Time to spare goes to measuring first: with ``v_fine`` > 0, the measuring parts
    are driven as slowly as the time left allows once the fast parts are reckoned at
    ``FAST_SHARE`` of ``v_max``, down to ``v_fine`` (a robot of a short segment reads its
    edges and algae ends to a few millimetres instead of idling along its fast parts);
    with no time to spare they keep ``v_measure``."""
    slow_v = min(v_max, v_measure)
    if v_fine > 0.0 and slow_m > 0.0:
        spare = time_left_s - fast_m / (FAST_SHARE * v_max)
        if spare * slow_v > slow_m:
            slow_v = max(min(v_fine, slow_v), slow_m / spare)
    budget = time_left_s - slow_m / slow_v
    v = v_max if budget <= 0.0 or fast_m <= 0.0 else min(v_max, fast_m / budget)
    v = max(v, min(v_floor, v_max))
    return min(v, slow_v) if measuring else v


def limit_lead(phase_des: float, phase: float, max_lead: float) -> float:
    """Keep the desired phase within ``max_lead`` of the robot's actual phase, so a
    robot that cannot keep up (saturated, blocked) does not wind up a lead it would
    later chase at full speed; the consensus then slows its neighbours to it."""
    lead = wrap_pi(phase_des - phase)
    if lead > max_lead:
        return wrap_2pi(phase + max_lead)
    if lead < -max_lead:
        return wrap_2pi(phase - max_lead)
    return phase_des
