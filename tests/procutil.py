"""Helpers for process tests: a private namespace and loopback port per test, a test
session with multicast off, and ending every process by its own pid."""

from __future__ import annotations

import json
import os
import signal
import socket
import subprocess
import sys
import time
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import zenoh

from deploy.procs import free_port
from wire.session import SessionOptions, open_session


def unique_ns() -> str:
    return f"btrack/test-{uuid.uuid4().hex[:12]}"


def hub_session(ns: str, port: int) -> zenoh.Session:
    return open_session(SessionOptions(ns=ns, mode="peer", listen=(f"tcp/127.0.0.1:{port}",),
                                       multicast=False))


def member_args(ns: str, port: int) -> list[str]:
    return ["--ns", ns, "--mode", "peer", "--connect", f"tcp/127.0.0.1:{port}",
            "--listen", "tcp/127.0.0.1:0", "--no-multicast"]


def start(args: list[str], log: Path | None = None,
          code: str | None = None) -> subprocess.Popen[bytes]:
    """``python -m btrack ARGS``, or ``python -c CODE ARGS`` (code that runs btrack after
    changing something below a process's boundary, as a test's fault)."""
    err = open(log, "wb") if log else subprocess.DEVNULL  # noqa: SIM115
    how = ["-m", "btrack"] if code is None else ["-c", code]
    return subprocess.Popen([sys.executable, *how, *args], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=err, start_new_session=True)


def end(proc: subprocess.Popen[bytes] | subprocess.Popen[str], grace_s: float = 5.0) -> None:
    """End a process we started, by its pid: SIGTERM, then SIGKILL. One that has already
    exited (and been reaped) is left alone: its pid may be someone else's by now."""
    if proc.poll() is not None:
        return
    kill_pid(proc.pid, grace_s, proc)


def kill_pid(pid: int, grace_s: float = 5.0,
             proc: subprocess.Popen[bytes] | subprocess.Popen[str] | None = None) -> None:
    try:
        os.kill(pid, signal.SIGTERM)
    except ProcessLookupError:
        return
    deadline = time.monotonic() + grace_s
    while time.monotonic() < deadline:
        if proc is not None:
            if proc.poll() is not None:
                return
        elif not pid_alive(pid):
            return
        time.sleep(0.05)
    try:
        os.kill(pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    if proc is not None:
        proc.wait()


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie of someone else's is dead for our purpose
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def run_sim(out: Path, *extra: str, timeout: float = 400, quiet: bool = True,
            scene: bool = False) -> subprocess.CompletedProcess[str]:
    """``btrack sim --out OUT [--quiet] EXTRA...`` to its end; every process it started
    is ended whatever happens. Without ``scene`` the run skips the Foxglove channels
    (``--no-scene``): the tests that measure a run do not pay for its view."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "btrack", "sim", "--out", str(out),
         *(["--quiet"] if quiet else []), *([] if scene else ["--no-scene"]), *extra],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )
    try:
        stdout, stderr = proc.communicate(timeout=timeout)
    finally:
        end(proc)
        end_children_of_run(out)
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)


def end_children_of_run(out: Path) -> list[int]:
    """End every process a launcher recorded in OUT/logs/pids.json; returns the pids."""
    path = out / "logs" / "pids.json"
    if not path.exists():
        return []
    pids = list(json.loads(path.read_text()).values())
    for pid in pids:
        kill_pid(pid)
    return pids


def wait_for(cond: Callable[[], bool], timeout: float, what: str) -> None:
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout} s waiting for {what}")
        time.sleep(0.02)


def open_when_accepted(conf: dict[str, Any], router: subprocess.Popen[bytes],
                       log: Path, timeout: float, what: str) -> zenoh.Session:
    """A session of ``conf`` (a Zenoh configuration), opened once the router accepts it
    (an mTLS router refuses a client until it listens); the router's log if it died."""
    opened: list[zenoh.Session] = []

    def joins() -> bool:
        assert router.poll() is None, log.read_text()[-2000:]
        try:
            opened.append(zenoh.open(zenoh.Config.from_json5(json.dumps(conf))))
        except zenoh.ZError:
            return False
        return True

    wait_for(joins, timeout, what)
    return opened[0]


@contextmanager
def taken_port() -> Iterator[int]:
    """A loopback port something listens on (a plain socket, speaking no Zenoh) for the
    block's length."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield int(s.getsockname()[1])


def wait_port(port: int, timeout_s: float = 60.0) -> None:
    """Wait until something listens on loopback ``port`` (a run's router)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise AssertionError(f"nothing listens on {port}")


def run_attacked(out: Path, sim_args: list[str], forger: str, lie_at: int,
                 timeout: float = 300) -> tuple[subprocess.CompletedProcess[str], str]:
    """``btrack sim`` to its end on a private namespace and port with a forger process
    (``python -m FORGER --ns --connect --at LIE_AT``) on its bus from the moment its router
    listens; the run and what the forger printed. Every process is ended by its pid."""
    ns, port = unique_ns(), free_port()
    sim = subprocess.Popen(
        [sys.executable, "-m", "btrack", "sim", "--out", str(out), "--quiet", *sim_args,
         "--ns", ns, "--port", str(port), "--no-scene"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    liar = None
    try:
        wait_port(port)
        liar = subprocess.Popen(
            [sys.executable, "-m", forger, "--ns", ns, "--connect", f"tcp/127.0.0.1:{port}",
             "--at", str(lie_at)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
        stdout, stderr = sim.communicate(timeout=timeout)
        assert liar.poll() is None, liar.communicate()[1]  # it lied and waits to be ended
    finally:
        end(sim)  # type: ignore[arg-type]
        end_children_of_run(out)
        if liar is not None:
            end(liar)  # type: ignore[arg-type]
    assert liar.stdout is not None
    return subprocess.CompletedProcess(sim.args, sim.returncode, stdout, stderr), \
        liar.stdout.read()


def timing_parted(run_dir: Path) -> list[str]:
    """What made a lockstep run's result depend on timing, from its processes' closing
    lines: the world stepping without a live agent's command (past ``--cmd-timeout``),
    an agent acting without a neighbour's state (past ``--neighbour-timeout``). Empty:
    the run is the one its seed gives, bit for bit."""
    logs = run_dir / "logs"
    why = []
    world = json.loads((logs / "world.out").read_text().strip().splitlines()[-1])
    if world["timeouts"]:
        why.append(f"the world stepped {world['timeouts']} time(s) without a command")
    for out in sorted(logs.glob("agent*.out")):
        lines = out.read_text().strip().splitlines()
        last = json.loads(lines[-1]) if lines else {}
        if last.get("timeouts"):
            why.append(f"agent {last['agent']} acted {last['timeouts']} time(s) without "
                       "a neighbour's state")
        if last.get("faults"):
            why.append(f"agent {last['agent']} gave up {last['faults']} tick(s) for a "
                       "fault of its own")
    return why


def wait_for_world(run_dir: Path, launcher: subprocess.Popen[str], timeout_s: float = 60
                   ) -> dict[str, int]:
    """The pids a launcher recorded in RUN_DIR/logs/pids.json, once its world is started;
    fails at once if the launcher ends first."""
    pids_file = run_dir / "logs" / "pids.json"
    deadline = time.monotonic() + timeout_s
    while not (pids_file.exists() and "world" in pids_file.read_text()):
        assert launcher.poll() is None, launcher.communicate()[1]
        assert time.monotonic() < deadline, f"no world started in {run_dir}"
        time.sleep(0.1)
    pids: dict[str, int] = json.loads(pids_file.read_text())
    return pids


__all__ = ["end", "end_children_of_run", "free_port", "hub_session", "kill_pid", "member_args",
           "pid_alive", "run_attacked", "run_sim", "start", "unique_ns", "wait_for",
           "wait_for_world", "wait_port"]
