"""The ``btrack`` command: one subcommand per process or tool.

Each subcommand lives in its own package and is imported only when used, so
``btrack agent`` on a robot computer never loads the simulator or matplotlib.
"""

from __future__ import annotations

import importlib
import sys

from wire.errors import BusError

COMMANDS: dict[str, tuple[str, str]] = {
    "sim": ("deploy.launcher", "run a simulated team: world, recorder and N agents"),
    "agent": ("agent.process", "one robot's controller (meant for the robot's own computer)"),
    "world": ("simworld.process", "the simulator: maps, kinematics, sensors, the clock"),
    "maps": ("simworld.mapgen", "write seeded procedural maps as PNG files, with maps.json"),
    "localizer": ("localizer.process", "laser localisation: one particle filter per robot"),
    "record": ("recorder.process", "record everything on the bus into an MCAP file"),
    "report": ("report.cli", "measures, summary.json and figures from a recorded run"),
    "scene": ("scene.cli", "add Foxglove's channels to a recording, or draw them (--png)"),
    "replay": ("replay.process", "put a recording's messages back on the bus"),
    "view": ("scene.live", "serve a running team to Foxglove over its WebSocket protocol"),
    "suite": ("deploy.suite", "the thesis's twelve cases, or general: random maps x teams"),
    "router": ("deploy.router", "a Zenoh router (the base station's), TLS and access control"),
    "deploy": ("deploy.cli", "a fleet's configurations, units and certificates from FLEET.toml"),
    "bridge": ("hwbridge.cli", "real devices on the bus: iRobot Create, SICK LMS 2xx"),
}


def dispatch(prog: str, commands: dict[str, tuple[str, str]], argv: list[str]) -> int:
    """Run ``argv[0]``'s module's ``main`` on the rest, importing only that module;
    help with no command, a clear error (exit 2) for an unknown one. Also serves the
    subcommands of ``btrack bridge``."""
    width = max(map(len, commands)) + 1
    lines = [f"usage: {prog} COMMAND [options]   ({prog} COMMAND --help for each)", "",
             "commands:"]
    lines += [f"  {name:<{width}} {help_}" for name, (_, help_) in commands.items()]
    usage = "\n".join(lines)
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage)
        return 0
    name, rest = argv[0], argv[1:]
    if name not in commands:
        print(f"{prog}: unknown command {name!r}\n\n{usage}", file=sys.stderr)
        return 2
    module = importlib.import_module(commands[name][0])
    try:
        return int(module.main(rest) or 0)
    except BusError as exc:
        print(f"{prog} {name}: {exc}", file=sys.stderr)
        return 1


def main(argv: list[str] | None = None) -> int:
    return dispatch("btrack", COMMANDS, sys.argv[1:] if argv is None else argv)
