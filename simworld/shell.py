"""The process shell every world shares: ``btrack world`` (``simworld.process``) and the
hardware loop's ``btrack bridge hil-world`` (``hwbridge.hil_world``).

Around a ``World`` it keeps the team's membership as the bus tells it (agents'
liveliness tokens, the recorder's and the localizer's), one queue of events that
Zenoh callbacks only push into, the Tick and WorldInfo publishers, whether the run
may begin, and the map check before a world is built. Each world adds its own clock
(the lockstep, or physics on the wall clock behind emulated devices).
"""

from __future__ import annotations

import argparse
import logging
import queue
import sys
from typing import Any

import zenoh

from simworld.maps import GridMap, MapError, load_map
from simworld.world import World
from wire import Keys, WorldInfo, encode
from wire.session import declare_publisher

log = logging.getLogger("btrack.world")

# queue items, built on Zenoh threads: (kind, key, payload-or-flag)
ALIVE, RECORDER, LOCALIZER, STOP = "alive", "recorder", "localizer", "stop"
Event = tuple[str, str, Any]


def load_checked_map(args: argparse.Namespace, prog: str) -> GridMap | None:
    """The run's map with room for the robots and the laser; None, said on stderr, if
    there is none."""
    try:
        gmap = load_map(args.map, args.scale, args.seed)
        gmap.check_room()
    except MapError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return None
    return gmap


class WorldShell:
    """Membership, the event queue and the run's announcements of one world process.

    ``team`` is the ids that must be alive before the run begins (default all of the
    world's robots); ``localization`` and ``realtime`` are what WorldInfo says of the
    run; with ``localizer`` the run also waits for the localizer's token."""

    def __init__(self, args: argparse.Namespace, world: World, session: zenoh.Session, *,
                 localization: str, realtime: bool, localizer: bool = False,
                 team: int | None = None) -> None:
        self.args = args
        self.world = world
        self.n = world.n
        self.team = set(range(team if team else world.n))
        self.dt = float(args.dt)
        self.keys = keys = Keys(args.ns)
        self.localization = localization
        self.realtime = realtime
        self.needs_localizer = localizer
        self.events: queue.SimpleQueue[Event] = queue.SimpleQueue()
        self.live: set[int] = set()
        self.rejected = 0  # well-formed but implausible input: foreign tokens
        self.recorder_alive = False
        self.localizer_alive = False
        self.stopping = False
        self.first_k = 0  # the run's first tick (WorldInfo.first_k)
        self.pub_tick = declare_publisher(session, keys.world_tick())
        self.pub_info = declare_publisher(session, keys.world_info())
        put = self.events.put

        def token(kind: str) -> Any:
            return lambda s: put((kind, str(s.key_expr), s.kind == zenoh.SampleKind.PUT))

        liveliness = session.liveliness()
        self._membership_subs = [
            liveliness.declare_subscriber(keys.alive("*"), token(ALIVE), history=True),
            liveliness.declare_subscriber(keys.alive_recorder(), token(RECORDER), history=True),
            *([liveliness.declare_subscriber(keys.alive_localizer(), token(LOCALIZER),
                                             history=True)] if localizer else []),
        ]

    def stop(self) -> None:
        """Called from a signal handler: wake whoever waits on the queue; end the run."""
        self.stopping = True
        self.events.put((STOP, "", None))

    def membership(self, item: Event) -> bool:
        """Apply a liveliness event; whether ``item`` was one."""
        kind, key, value = item
        if kind == ALIVE:
            robot = Keys.robot_of(key)
            if robot is not None and 0 <= robot < self.n:
                (self.live.add if value else self.live.discard)(robot)
                self.joined(robot, bool(value))
                log.info("agent %d %s", robot, "alive" if value else "gone")
            elif value:  # a token for a robot this world does not have: never waited for
                self.rejected += 1
                log.warning("refused a liveliness token %s: no such robot here (0..%d)",
                            key, self.n - 1)
        elif kind == RECORDER:
            self.recorder_alive = bool(value)
        elif kind == LOCALIZER:
            self.localizer_alive = bool(value)
            log.info("localizer %s", "alive" if value else "gone")
        else:
            return False
        return True

    def joined(self, robot: int, up: bool) -> None:
        """A robot's agent came (``up``) or went; for the world's own bookkeeping."""

    def ready(self) -> bool:
        """Whether the run may begin: the team, and the recorder and the localizer if
        the run waits for them, are alive."""
        return (self.live >= self.team
                and (self.recorder_alive or not self.args.wait_recorder)
                and (self.localizer_alive or not self.needs_localizer))

    def waiting_for(self) -> str:
        """Who the run still waits for, for the message of a startup timeout."""
        missing = sorted(self.team - self.live)
        if missing:
            return f"agents {missing}"
        if self.args.wait_recorder and not self.recorder_alive:
            return "the recorder"
        return "the localizer" if self.needs_localizer and not self.localizer_alive else ""

    def publish_info(self) -> None:
        a = self.args
        self.pub_info.put(encode(WorldInfo(
            map=self.world.map.name,  # a procedural map's full spec, which rebuilds it
            start=a.start, robots=self.n, localization=self.localization, seed=a.seed,
            duration_s=a.duration, dt=self.dt, realtime=self.realtime, first_k=self.first_k,
            **self.world.info())))  # type: ignore[arg-type]
