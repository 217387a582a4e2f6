"""Process tests of ``btrack world``: a real subprocess on a private namespace and a
loopback port, driven by a stand-in agent in the test."""

from __future__ import annotations

import json
import os
import queue
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import zenoh

from tests.procutil import free_port
from wire import Cmd, Keys, Sense, Tick, decode, encode

ROOT = Path(__file__).resolve().parents[1]
MSGPACK = zenoh.Encoding("application/msgpack")


@contextmanager
def world_process(*extra: str) -> Iterator[tuple[subprocess.Popen[str], Keys, int]]:
    port = free_port()
    ns = f"test/simworld-{uuid.uuid4().hex[:8]}"
    cmd = [
        sys.executable,
        "-m",
        "btrack",
        "world",
        "--no-multicast",
        "--listen",
        f"tcp/127.0.0.1:{port}",
        "--ns",
        ns,
        *extra,
    ]
    proc = subprocess.Popen(
        cmd, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        yield proc, Keys(ns), port
    finally:
        if proc.poll() is None:
            os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
        for stream in (proc.stdout, proc.stderr):
            if stream:
                stream.close()


def _session(port: int) -> zenoh.Session:
    conf = zenoh.Config()
    conf.insert_json5("mode", '"peer"')
    conf.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{port}"]))
    conf.insert_json5("scouting/multicast/enabled", "false")
    return zenoh.open(conf)


def _summary(proc: subprocess.Popen[str]) -> dict[str, object]:
    out, err = proc.communicate(timeout=20)
    assert proc.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])


def test_world_lockstep_one_agent_survives_garbage() -> None:
    with world_process(
        "--robots",
        "1",
        "--duration",
        "1",
        "--dt",
        "0.1",
        "--cmd-timeout",
        "10",
        "--startup-timeout",
        "20",
    ) as (proc, keys, port):
        events: queue.SimpleQueue[tuple[str, bytes]] = queue.SimpleQueue()
        with _session(port) as s:
            s.declare_subscriber(
                keys.sense(0), lambda m: events.put(("sense", m.payload.to_bytes()))
            )
            s.declare_subscriber(
                keys.world_tick(), lambda m: events.put(("tick", m.payload.to_bytes()))
            )
            pub = s.declare_publisher(keys.cmd(0), encoding=MSGPACK)
            token = s.liveliness().declare_token(keys.alive(0))
            ticks: list[Tick] = []
            senses: list[int] = []
            deadline = time.monotonic() + 30
            while not (ticks and ticks[-1].done):
                kind, payload = events.get(timeout=max(0.01, deadline - time.monotonic()))
                if kind == "sense":
                    sense = decode(Sense, payload)
                    senses.append(sense.k)
                    if sense.k == 0:
                        pub.put(b"\xc1 garbage, not msgpack")
                        pub.put(encode(Cmd(sense.t, sense.k + 5, 0, 0.1, 0.0)))  # other tick
                    pub.put(encode(Cmd(sense.t, sense.k, 0, 0.5, 0.0)))
                else:
                    ticks.append(decode(Tick, payload))
            summary = _summary(proc)
            token.undeclare()
    assert [t.k for t in ticks] == list(range(10)) and senses == list(range(10))
    assert [t.done for t in ticks] == [False] * 9 + [True]
    assert all(t.live == [0] for t in ticks)
    assert abs(ticks[3].t - 0.3) < 1e-12
    assert summary["ticks"] == 10 and summary["dropped"] == 1 and summary["timeouts"] == 0


def test_world_drops_agent_that_leaves() -> None:
    """Agent 1's token goes away mid-run: the world stops waiting for it at once
    (a 30 s command timeout would show as a stall) and lists only agent 0 as live."""
    with world_process(
        "--robots",
        "2",
        "--duration",
        "0.6",
        "--cmd-timeout",
        "30",
        "--startup-timeout",
        "20",
        "--map",
        "no-algae",
    ) as (proc, keys, port):
        events: queue.SimpleQueue[tuple[str, bytes]] = queue.SimpleQueue()
        with _session(port) as s:
            for i in (0, 1):
                s.declare_subscriber(
                    keys.sense(i), lambda m: events.put(("sense", m.payload.to_bytes()))
                )
            s.declare_subscriber(
                keys.world_tick(), lambda m: events.put(("tick", m.payload.to_bytes()))
            )
            pubs = [s.declare_publisher(keys.cmd(i), encoding=MSGPACK) for i in (0, 1)]
            tokens = [s.liveliness().declare_token(keys.alive(i)) for i in (0, 1)]
            ticks: list[Tick] = []
            deadline = time.monotonic() + 30
            while not (ticks and ticks[-1].done):
                kind, payload = events.get(timeout=max(0.01, deadline - time.monotonic()))
                if kind == "sense":
                    sense = decode(Sense, payload)
                    if sense.robot == 1 and sense.k == 2:
                        tokens[1].undeclare()  # leave without answering tick 2
                    elif sense.robot == 0 or sense.k < 2:
                        pubs[sense.robot].put(encode(Cmd(sense.t, sense.k, sense.robot, 0.2, 0.0)))
                else:
                    ticks.append(decode(Tick, payload))
            summary = _summary(proc)
            tokens[0].undeclare()
    assert [t.k for t in ticks] == list(range(6))
    assert ticks[0].live == [0, 1] and ticks[-1].live == [0]
    assert all(t.waited_ms < 10_000 for t in ticks)
    assert summary["timeouts"] == 0


def test_world_bad_map_exits_2_without_traceback(tmp_path: Path) -> None:
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a png")
    run = subprocess.run(
        [sys.executable, "-m", "btrack", "world", "--map", str(bad), "--no-multicast"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=30,
    )
    assert run.returncode == 2
    assert "cannot read map image" in run.stderr and "Traceback" not in run.stderr


def test_world_refuses_a_negative_hold_timeout() -> None:
    run = subprocess.run(
        [sys.executable, "-m", "btrack", "world", "--hold-at", "5", "--hold-timeout", "-1",
         "--no-multicast"],
        cwd=ROOT, capture_output=True, text=True, timeout=30,
    )
    assert run.returncode == 2
    assert "--hold-timeout must be >= 0" in run.stderr and "Traceback" not in run.stderr
