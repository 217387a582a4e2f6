"""Phase along the patrol cycle: eq. 3.1 (corrected), wrapping, the desired-phase
update with feedback linearisation and chain consensus (eq. 4.5-4.8) and the speed
law (eq. 4.10)."""

from __future__ import annotations

import math

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


def speed_law(phase_des: float, phase: float, k_v: float, v_max: float) -> float:
    """Forward speed tracking the desired phase, thesis eq. 4.10, within [0, v_max]:
    a robot ahead of its desired phase waits rather than backing up its patrol."""
    return min(max(k_v * wrap_pi(phase_des - phase), 0.0), v_max)


def patrol_speed(phase_des: float, phase: float, on_leg: bool, measuring: bool, k_v: float,
                 v_max: float, v_measure: float) -> float:
    """Forward speed along the patrol. In the arcs, eq. 4.10 tracks the desired phase.
    On a straight leg across the edge the position phase of eq. 3.1 does not move, so
    eq. 4.10 has nothing to track there: its speed would grow only with the lag the leg
    itself builds up, and a robot would crawl out of every turn and hand its neighbours
    that lag as phase error. A robot behind its desired phase runs its legs at full
    speed instead and leaves the tracking to the arcs, except while ``measuring`` (near
    where the leg expects the algae to end): there it goes no faster than eq. 4.10 or
    ``v_measure``, whichever is faster, as one 10 Hz tick at full speed is 5 cm of
    depth. A robot ahead of its desired phase waits, as in eq. 4.10."""
    law = speed_law(phase_des, phase, k_v, v_max)
    if not on_leg or wrap_pi(phase_des - phase) <= 0.0:
        return law
    if measuring:
        return min(v_max, max(law, v_measure))
    return v_max


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
