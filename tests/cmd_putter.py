"""A robot computer's process that only puts its robot's command, for the tests of a
certificate's expiry across hosts: ``python tests/cmd_putter.py CONFIG.json5 --ns NS
--robot I --until UNIX_S --expires UNIX_S``. It opens a session with the given Zenoh
configuration (exit 3, saying "cannot open", if it cannot), says "opened", then puts a
stopped command (t = 0, so that it is told apart from an agent's) on robot I's command
key every 20 ms until ``--until``, and prints how many it put, and how many of them
after ``--expires``, as one JSON line."""

from __future__ import annotations

import argparse
import json
import sys
import time

import zenoh

from wire import Cmd, Keys, encode

PERIOD_S = 0.02


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("config")
    p.add_argument("--ns", required=True)
    p.add_argument("--robot", type=int, required=True)
    p.add_argument("--until", type=float, required=True, help="Unix seconds to put until")
    p.add_argument("--expires", type=float, required=True,
                   help="Unix seconds the certificate expires at (for the count)")
    a = p.parse_args()
    try:
        session = zenoh.open(zenoh.Config.from_file(a.config))
    except Exception as exc:
        print(f"cannot open: {exc}", flush=True)
        return 3
    print("opened", flush=True)
    key = Keys(a.ns).cmd(a.robot)
    sent = after = 0
    while time.time() < a.until:
        session.put(key, encode(Cmd(0.0, 0, a.robot, 0.0, 0.0)))
        sent += 1
        after += time.time() > a.expires
        time.sleep(PERIOD_S)
    print(json.dumps({"sent": sent, "sent_after_expiry": after}), flush=True)
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
