"""Key expressions, all under one run namespace so teams and test runs never mix.

One table (``TOPICS``) says every key of the contract: its pattern under the namespace
and the message type it carries (none for liveliness tokens and the recorder's
queryable). ``Keys`` builds the keys from it, their wildcard patterns (for access
control) and parses a key back to its topic and robot; the recorder's topic-to-type
table and the access-control rules are generated from it, never written again."""

from __future__ import annotations

import re
from dataclasses import dataclass

from wire import messages

_NS_RE = re.compile(r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$")


@dataclass(frozen=True)
class Topic:
    """One key of the contract: ``path`` under the namespace, ``{robot}`` where a robot
    id goes, and the message type it carries (None: a token or a queryable)."""

    name: str
    path: str
    message: type | None

    @property
    def per_robot(self) -> bool:
        return "{robot}" in self.path

    def at(self, robot: int | str | None = None) -> str:
        """The path (under the namespace) for ``robot`` (``"*"``: any robot)."""
        if self.per_robot:
            if robot is None:
                raise ValueError(f"topic {self.name} needs a robot")
            return self.path.replace("{robot}", str(robot))
        return self.path


TOPICS: dict[str, Topic] = {t.name: t for t in (
    Topic("sense", "robot/{robot}/sense", messages.Sense),  # world/bridge -> robot i
    Topic("pose", "robot/{robot}/pose", messages.Pose),  # localizer (or world) -> agent i
    # localizer -> recorder and viewers, when asked: a sample of robot i's particles
    Topic("particles", "robot/{robot}/particles", messages.Particles),
    Topic("cmd", "robot/{robot}/cmd", messages.Cmd),  # agent i -> its robot
    Topic("state", "agent/{robot}/state", messages.AgentState),  # agent i -> neighbours
    # world/bridge -> localizer: each scanner's scan of each tick, numbered in the Scan
    Topic("scan", "laser/scan", messages.Scan),
    Topic("truth", "world/truth", messages.Truth),  # world -> recorder: every robot's
    Topic("world_tick", "world/tick", messages.Tick),
    Topic("world_info", "world/info", messages.WorldInfo),
    Topic("fault", "fault", messages.Fault),  # launcher -> recorder: faults it injected
    Topic("alive", "alive/agent/{robot}", None),  # agent i's liveliness: membership
    Topic("alive_recorder", "alive/recorder", None),
    Topic("alive_localizer", "alive/localizer", None),
    Topic("progress", "recorder/progress", None),  # the recorder's queryable
)}
_ROBOT_ID = re.compile(r"^[0-9]+$")


@dataclass(frozen=True)
class Keys:
    """All key expressions of one run namespace (e.g. ``btrack/lab1``)."""

    ns: str = "btrack"

    def __post_init__(self) -> None:
        if not _NS_RE.match(self.ns):
            raise ValueError(
                f"bad namespace {self.ns!r}: use letters, digits, '-', '_' and '/' separators"
            )

    def key(self, topic: str, robot: int | str | None = None) -> str:
        """The key of ``topic`` (a name of ``TOPICS``), for ``robot`` if it is per robot
        (``"*"``: a pattern matching every robot's)."""
        return f"{self.ns}/{TOPICS[topic].at(robot)}"

    def pattern(self, topic: str) -> str:
        """The wildcard key matching ``topic`` of every robot (the key itself if the
        topic is not per robot)."""
        return self.key(topic, "*" if TOPICS[topic].per_robot else None)

    def parse(self, key: str) -> tuple[Topic, int | None] | None:
        """The topic and robot id of a key of this namespace, None if it is none."""
        prefix = self.ns + "/"
        return parse_path(key[len(prefix):]) if key.startswith(prefix) else None

    def sense(self, robot: int | str) -> str:
        return self.key("sense", robot)

    def pose(self, robot: int | str) -> str:
        return self.key("pose", robot)

    def particles(self, robot: int | str) -> str:
        return self.key("particles", robot)

    def cmd(self, robot: int | str) -> str:
        return self.key("cmd", robot)

    def scan(self) -> str:
        return self.key("scan")

    def truth(self) -> str:
        return self.key("truth")

    def state(self, robot: int | str) -> str:
        return self.key("state", robot)

    def alive(self, robot: int | str) -> str:
        return self.key("alive", robot)

    def alive_recorder(self) -> str:
        return self.key("alive_recorder")

    def alive_localizer(self) -> str:
        return self.key("alive_localizer")

    def world_tick(self) -> str:
        return self.key("world_tick")

    def world_info(self) -> str:
        return self.key("world_info")

    def fault(self) -> str:
        return self.key("fault")

    def progress(self) -> str:
        """The recorder's queryable: a Progress of the run so far."""
        return self.key("progress")

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


def _matcher(topic: Topic) -> re.Pattern[str]:
    return re.compile("^" + re.escape(topic.path).replace(re.escape("{robot}"), "([0-9]+)")
                      + "$")


_MATCHERS = [(t, _matcher(t)) for t in TOPICS.values()]


def parse_path(path: str) -> tuple[Topic, int | None] | None:
    """The topic and robot id of a path under the namespace (a recording's topic name),
    None if it is no topic of the contract."""
    for topic, matcher in _MATCHERS:
        found = matcher.match(path)
        if found:
            return topic, (int(found.group(1)) if topic.per_robot else None)
    return None
