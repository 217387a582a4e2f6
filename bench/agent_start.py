"""How long an agent process takes to start: from spawning ``btrack agent`` to its
liveliness token on the bus, the moment its neighbours and the world see it. The
simulator charges a restarted or joining agent this much simulated time
(``btrack sim --boot-s``), holding its clock while the real process starts.

    .venv/bin/python bench/agent_start.py [--starts 10]
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import threading
import time
import uuid

import zenoh

from deploy.procs import free_port
from wire import Keys
from wire.session import SessionOptions, open_session


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--starts", type=int, default=10)
    args = p.parse_args()
    ns, port = f"btrack/bench-{uuid.uuid4().hex[:8]}", free_port()
    keys = Keys(ns)
    opts = SessionOptions(ns=ns, mode="peer", listen=(f"tcp/127.0.0.1:{port}",),
                          multicast=False)
    member = ["--ns", ns, "--mode", "peer", "--connect", f"tcp/127.0.0.1:{port}",
              "--listen", "tcp/127.0.0.1:0", "--no-multicast"]
    times = []
    with open_session(opts) as session:
        for _ in range(args.starts):
            seen = threading.Event()
            def on_token(sample: zenoh.Sample, seen: threading.Event = seen) -> None:
                if sample.kind == zenoh.SampleKind.PUT:
                    seen.set()

            sub = session.liveliness().declare_subscriber(keys.alive(0), on_token)
            began = time.monotonic()
            proc = subprocess.Popen(
                [sys.executable, "-m", "btrack", "agent", "--id", "0", "--robots", "1", *member],
                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
            try:
                if not seen.wait(60):
                    raise SystemExit("the agent's token never came")
                times.append(time.monotonic() - began)
            finally:
                proc.terminate()
                proc.wait(10)
                sub.undeclare()
            time.sleep(0.3)
    print(f"agent start, spawn to liveliness token, {len(times)} starts: "
          f"median {statistics.median(times):.2f} s, min {min(times):.2f} s, "
          f"max {max(times):.2f} s")


if __name__ == "__main__":
    main()
