"""``btrack bridge``: real devices on the bus (and the emulated ones of ``btrack sim --hil``).

Subcommands: ``create`` (one per robot computer), ``lms`` (the base station's laser),
``hil-world`` (the simulator's physics behind emulated devices on pseudo-terminals).
"""

from __future__ import annotations

import importlib
import sys

SUBCOMMANDS: dict[str, tuple[str, str]] = {
    "create": ("hwbridge.create_bridge", "an iRobot Create / Create 2 on a serial port"),
    "lms": ("hwbridge.lms_bridge", "a SICK LMS 2xx on a serial port"),
    "hil-world": ("hwbridge.hil_world",
                  "simulated physics behind emulated Creates and LMS on pseudo-terminals"),
}


def usage() -> str:
    lines = ["usage: btrack bridge SUBCOMMAND [options]   (--help on each)", "",
             "subcommands:"]
    lines += [f"  {name:<10} {help_}" for name, (_, help_) in SUBCOMMANDS.items()]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv or argv[0] in ("-h", "--help", "help"):
        print(usage())
        return 0
    name, rest = argv[0], argv[1:]
    if name not in SUBCOMMANDS:
        print(f"btrack bridge: unknown subcommand {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    return int(importlib.import_module(SUBCOMMANDS[name][0]).main(rest) or 0)
