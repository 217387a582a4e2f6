"""Fault schedules for ``btrack sim``: what to do to which agent at which simulated
time. Pure: parsing ``--fault`` specs, drawing a ``--chaos`` schedule from a seed, and
deciding which faults are due at a tick. The launcher carries them out."""

from __future__ import annotations

import math
import random
import re
from dataclasses import dataclass

KINDS = ("kill", "restart", "freeze", "thaw", "join")
_SPEC = re.compile(r"^(kill|restart|freeze|join):(\d+)@(\d+(?:\.\d*)?)(?:-(\d+(?:\.\d*)?))?$")


class FaultSpecError(ValueError):
    """A --fault spec or schedule that cannot be carried out, with the reason."""


@dataclass(frozen=True, order=True)
class Fault:
    at_s: float  # simulated time
    kind: str  # kill | restart | freeze | thaw | join
    agent: int


def parse_fault(spec: str) -> list[Fault]:
    """``kill:1@120``, ``restart:1@300``, ``freeze:2@200-230`` (a freeze and its thaw),
    ``join:3@400``."""
    m = _SPEC.match(spec.strip())
    if not m:
        raise FaultSpecError(
            f"bad --fault {spec!r}: use kill:I@T, restart:I@T, freeze:I@T1-T2 or join:I@T "
            "(I an agent id, T simulated seconds)")
    kind, agent, at, until = m.group(1), int(m.group(2)), float(m.group(3)), m.group(4)
    if kind == "freeze":
        if until is None or float(until) <= at:
            raise FaultSpecError(f"bad --fault {spec!r}: freeze needs T1-T2 with T2 > T1")
        return [Fault(at, "freeze", agent), Fault(float(until), "thaw", agent)]
    if until is not None:
        raise FaultSpecError(f"bad --fault {spec!r}: only freeze takes a time range")
    return [Fault(at, kind, agent)]


def check_schedule(faults: list[Fault], team: int) -> int:
    """Refuse a schedule that cannot happen; return the number of robots the world
    needs (the starting team plus every id that joins)."""
    up = set(range(team))
    frozen: set[int] = set()
    known = set(range(team))
    for f in sorted(faults):
        where = f"{f.kind}:{f.agent}@{f.at_s:g}"
        if f.kind == "join":
            if f.agent in known:
                raise FaultSpecError(f"{where}: agent {f.agent} is already in the team "
                                     "(join is for new ids; use restart after a kill)")
            known.add(f.agent)
            up.add(f.agent)
        elif f.agent not in known:
            raise FaultSpecError(f"{where}: no agent {f.agent} (the team is 0..{team - 1}"
                                 " plus ids that join)")
        elif f.kind == "kill":
            if f.agent not in up:
                raise FaultSpecError(f"{where}: agent {f.agent} is not running then")
            up.discard(f.agent)
            frozen.discard(f.agent)
        elif f.kind == "restart":
            if f.agent in up:
                raise FaultSpecError(f"{where}: agent {f.agent} is still running (kill it "
                                     "first)")
            up.add(f.agent)
        elif f.kind == "freeze":
            if f.agent not in up or f.agent in frozen:
                raise FaultSpecError(f"{where}: agent {f.agent} is not running unfrozen then")
            frozen.add(f.agent)
        elif f.kind == "thaw":
            frozen.discard(f.agent)
    return max(known) + 1


def _tenth(t: float) -> float:
    return math.floor(t * 10.0) / 10.0


def chaos_schedule(seed: int, team: int, duration_s: float) -> list[Fault]:
    """Random kills (each restarted later) and freezes of random agents, from a seed:
    from a tenth into the run, a fault every 60 to 150 s; at least two agents stay up;
    everything is back up before the last fifth of the run."""
    rng = random.Random(seed)
    faults: list[Fault] = []
    down_until: dict[int, float] = {}
    t = 0.1 * duration_s + rng.uniform(0.0, 60.0)
    end = 0.8 * duration_s
    while t < end:
        up = [a for a in range(team) if down_until.get(a, -1.0) <= t]
        if len(up) > 2 or (len(up) == team and team >= 2):
            agent = rng.choice(up)
            if rng.random() < 0.5:
                back = min(t + rng.uniform(30.0, 120.0), end)
                faults += [Fault(_tenth(t), "kill", agent), Fault(_tenth(back), "restart", agent)]
            else:
                back = min(t + rng.uniform(5.0, 40.0), end)
                faults += [Fault(_tenth(t), "freeze", agent), Fault(_tenth(back), "thaw", agent)]
            down_until[agent] = back + 1.0
        t += rng.uniform(60.0, 150.0)
    return sorted(faults)


def due(faults: list[Fault], done: int, t: float) -> list[Fault]:
    """The faults of the sorted schedule after the first ``done`` that are due at ``t``."""
    out = []
    for f in faults[done:]:
        if f.at_s > t:
            break
        out.append(f)
    return out
