"""A process that hears one large message, for tests/test_session_memory.py: ``python
-m tests.shm_listener --ns NS --listen EP`` opens a session of ours (wire.session),
prints "ready", waits for a message on NS/big, then prints how many bytes it got and
whether Zenoh mapped a shared-memory segment into it (/proc/self/maps), and ends."""

from __future__ import annotations

import argparse
import json
import queue

from wire.session import SessionOptions, open_session


def zenoh_shm_mapped() -> bool:
    with open("/proc/self/maps") as f:
        return any("/dev/shm/" in line and ".zenoh" in line for line in f)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--ns", required=True)
    p.add_argument("--listen", required=True)
    args = p.parse_args()
    opts = SessionOptions(ns=args.ns, mode="peer", listen=(args.listen,), multicast=False)
    got: queue.SimpleQueue[bytes] = queue.SimpleQueue()
    with open_session(opts) as session:
        sub = session.declare_subscriber(f"{args.ns}/big",
                                         lambda s: got.put(s.payload.to_bytes()))
        print("ready", flush=True)
        payload = got.get(timeout=30)
        print(json.dumps({"bytes": len(payload), "shm": zenoh_shm_mapped()}), flush=True)
        sub.undeclare()


if __name__ == "__main__":
    main()
