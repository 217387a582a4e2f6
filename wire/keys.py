"""Key expressions, all under one run namespace so teams and test runs never mix."""

from __future__ import annotations

import re
from dataclasses import dataclass

_NS_RE = re.compile(r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$")


@dataclass(frozen=True)
class Keys:
    """All key expressions of one run namespace (e.g. ``btrack/lab1``)."""

    ns: str = "btrack"

    def __post_init__(self) -> None:
        if not _NS_RE.match(self.ns):
            raise ValueError(
                f"bad namespace {self.ns!r}: use letters, digits, '-', '_' and '/' separators"
            )

    # world -> robot i (simworld or hwbridge)
    def sense(self, robot: int | str) -> str:
        return f"{self.ns}/robot/{robot}/sense"

    # localizer (or world, for truth/odometry poses) -> agent i
    def pose(self, robot: int | str) -> str:
        return f"{self.ns}/robot/{robot}/pose"

    # agent i -> its robot
    def cmd(self, robot: int | str) -> str:
        return f"{self.ns}/robot/{robot}/cmd"

    # world/bridge -> localizer: one laser scan per tick (one scanner per team)
    def scan(self) -> str:
        return f"{self.ns}/laser/scan"

    # world -> recorder only: every robot's ground truth, one message per tick
    def truth(self) -> str:
        return f"{self.ns}/world/truth"

    # agent i -> its neighbours (and the recorder)
    def state(self, robot: int | str) -> str:
        return f"{self.ns}/agent/{robot}/state"

    # liveliness token of agent i; membership is read from these
    def alive(self, robot: int | str) -> str:
        return f"{self.ns}/alive/agent/{robot}"

    def alive_recorder(self) -> str:
        return f"{self.ns}/alive/recorder"

    def alive_localizer(self) -> str:
        return f"{self.ns}/alive/localizer"

    def world_tick(self) -> str:
        return f"{self.ns}/world/tick"

    def world_info(self) -> str:
        return f"{self.ns}/world/info"

    # launcher -> recorder: faults it injected
    def fault(self) -> str:
        return f"{self.ns}/fault"

    def progress(self) -> str:
        """The recorder's queryable: a Progress of the run so far."""
        return f"{self.ns}/recorder/progress"

    def everything(self) -> str:
        return f"{self.ns}/**"

    def relative(self, key: str) -> str:
        """The key without the namespace prefix (topic names in recordings)."""
        prefix = self.ns + "/"
        return key[len(prefix) :] if key.startswith(prefix) else key

    @staticmethod
    def robot_of(key: str) -> int | None:
        """The robot id in ``.../robot/I/...``, ``.../agent/I/...`` or ``.../alive/agent/I``."""
        parts = key.split("/")
        for i, part in enumerate(parts[:-1]):
            if part in ("robot", "agent") and parts[i + 1].isdigit():
                return int(parts[i + 1])
        return None
