"""Our sessions leave Zenoh's shared-memory transport off (issue 21, memory per agent):
Zenoh 1.x sends a message over 3 KB between two processes of one host through a 16 MB
shared-memory pool that the receiver maps whole, 16 MB more resident in every agent.
Two real processes on loopback: one of ours hears a 64 KB message and reports what
Zenoh mapped into it; with a configuration file that turns shared memory back on, the
same exchange maps the pool (so the check can fail)."""

from __future__ import annotations

import json
import os
import select
import subprocess
import sys
import time
from pathlib import Path

from deploy.procs import free_port
from tests.procutil import end, unique_ns
from wire.session import SessionOptions, open_session

SHM_ON = "{transport: {shared_memory: {enabled: true}}}"


def exchange(tmp_path: Path, config: str | None) -> dict[str, object]:
    """The listener's report after a 64 KB message from this process; ``config``: a
    Zenoh configuration file's text that both sides read, or ours alone."""
    ns, port = unique_ns(), free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    env, config_file = dict(os.environ), None
    if config is not None:
        config_file = tmp_path / "zenoh.json5"
        config_file.write_text(config)
        env["ZENOH_CONFIG"] = str(config_file)
    listener = subprocess.Popen([sys.executable, "-m", "tests.shm_listener", "--ns", ns,
                                 "--listen", endpoint], stdout=subprocess.PIPE, env=env)
    try:
        assert listener.stdout is not None
        assert listener.stdout.readline().strip() == b"ready"
        opts = SessionOptions(ns=ns, mode="peer", connect=(endpoint,), multicast=False,
                              config_file=str(config_file) if config_file else None)
        with open_session(opts, wait_s=30) as session:
            pub = session.declare_publisher(f"{ns}/big")
            deadline = time.monotonic() + 30
            heard: list[bytes] = []
            while not heard:  # a put before the link is up is lost: again until heard
                assert time.monotonic() < deadline, "the listener heard nothing"
                assert listener.poll() is None, "the listener ended"
                pub.put(bytes(64 * 1024))
                if select.select([listener.stdout], [], [], 0.2)[0]:
                    heard.append(listener.stdout.readline())
            pub.undeclare()
        return json.loads(heard[0])
    finally:
        end(listener)


def test_a_large_message_between_our_processes_maps_no_shared_memory(tmp_path):
    assert exchange(tmp_path, None) == {"bytes": 64 * 1024, "shm": False}


def test_with_shared_memory_turned_on_by_a_file_the_pool_is_mapped(tmp_path):
    assert exchange(tmp_path, SHM_ON) == {"bytes": 64 * 1024, "shm": True}
