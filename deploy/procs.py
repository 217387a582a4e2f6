"""Child processes of a launcher: started with subprocess (never forked after a
Zenoh session opened), in their own process group, logged to files, and always
ended by their own process id."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the launcher is, so it ends its children as on Ctrl-C."""


def _raise_terminated(signum: int, frame: object) -> None:
    raise Terminated()


def stop_on_sigterm() -> None:
    """Make SIGTERM (``kill PID``, ``timeout``, a service manager) end a launcher the way
    Ctrl-C does: through its ``except KeyboardInterrupt``, which stops every child.
    Without it the launcher dies at once and its children, in their own sessions,
    run on. SIGINT is taken back too: a launcher started in the background (``&``,
    ``nohup``, a suite that was) inherits SIGINT ignored, and then the suite's Ctrl-C to
    its launchers, or a test's, was lost, and they ran on with every child."""
    signal.signal(signal.SIGTERM, _raise_terminated)
    signal.signal(signal.SIGINT, signal.default_int_handler)


def interrupted_code(exc: KeyboardInterrupt) -> tuple[int, str]:
    """Exit code and word for a launcher stopped by Ctrl-C or by SIGTERM."""
    if isinstance(exc, Terminated):
        return 128 + signal.SIGTERM, "terminated"
    return 128 + signal.SIGINT, "interrupted"


def stop_interrupted(group: ProcessGroup, exc: KeyboardInterrupt, who: str) -> int:
    """Say why ``who`` stops, end every child of ``group``; the exit code (130 or 143)."""
    code, word = interrupted_code(exc)
    print(f"\n{who}: {word}; stopping every process", file=sys.stderr)
    group.stop_all()
    return code


ODOM_FLAGS = ("odom_noise", "odom_turn_noise")  # sim and suite pass them on to the world
# the agent options that sim, suite and the hardware loop pass on to every agent
AGENT_FLAGS = ("config", "k_s", "k_phi", "cycle_s", "passes")


def non_negative(text: str) -> float:
    """An argparse type: a float >= 0 (a noise), refused with the value at fault."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text}")
    return value


def forward_flags(args: argparse.Namespace, names: tuple[str, ...]) -> list[str]:
    """The options ``names`` that were given (the parser may lack some), as
    command-line flags for a child."""
    out: list[str] = []
    for name in names:
        value = getattr(args, name, None)
        if value is not None:
            out += ["--" + name.replace("_", "-"), str(value)]
    return out


# Where a listening port is drawn: under the kernel's ephemeral range, which every
# outgoing connection on the machine takes its local port from. A port the kernel
# handed out as free can be taken by one of them before the process that was to
# listen on it does (the test suite's Zenoh sessions open hundreds), and that process
# then cannot listen; a port under the range is taken only by another listener.
LISTEN_PORTS_FROM = 10000
EPHEMERAL_RANGE = Path("/proc/sys/net/ipv4/ip_local_port_range")


def ephemeral_low(path: Path = EPHEMERAL_RANGE) -> int | None:
    """The first port of the kernel's ephemeral range, None where it cannot be read."""
    try:
        return int(path.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return None


def bindable(port: int) -> bool:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        try:
            s.bind(("127.0.0.1", port))
        except OSError:
            return False
    return True


def free_port(draws: int = 64) -> int:
    """A TCP port on loopback that was free a moment ago: drawn at random under the
    ephemeral range where there is room, else (or if no draw was free) one the kernel
    picks."""
    low = ephemeral_low()
    if low is not None and low - LISTEN_PORTS_FROM >= 1000:
        rng = random.SystemRandom()
        for _ in range(draws):
            port = rng.randrange(LISTEN_PORTS_FROM, low)
            if bindable(port):
                return port
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def listening(port: int) -> bool:
    """Whether something accepts connections on loopback ``port``."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        return s.connect_ex(("127.0.0.1", port)) == 0


def wait_listening(port: int, child: Child, timeout_s: float) -> bool:
    """Until ``child`` accepts connections on loopback ``port`` (or has died)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and child.alive():
        if listening(port):
            return True
        time.sleep(0.05)
    return False


@dataclass
class Child:
    name: str
    proc: subprocess.Popen[bytes]
    log_path: Path
    stdout_path: Path

    @property
    def pid(self) -> int:
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc.poll() is None

    def last_json(self) -> dict[str, Any]:
        """The last line the process printed, as the JSON object of counts every btrack
        process ends with; {} if there is none (yet)."""
        try:
            lines = self.stdout_path.read_text().strip().splitlines()
            value = json.loads(lines[-1]) if lines else {}
        except (OSError, ValueError):
            return {}
        return value if isinstance(value, dict) else {}

    def log_tail(self, lines: int = 15) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-lines:])
        except OSError:
            return ""


def own_faults(children: list[Child]) -> str | None:
    """A line naming the agents that counted faults of their own (an exception of our
    code that cost a tick: a bug to report, with their logs), from their closing lines;
    None if there were none."""
    faulty = [f"{c.name} {n} ({c.log_path})" for c in children
              if c.name.startswith("agent") and (n := c.last_json().get("faults"))]
    if not faulty:
        return None
    return ("faults of our own code, each a tick stood still (a bug: please report it, "
            "with the log): " + ", ".join(faulty))


@dataclass
class ProcessGroup:
    """All processes a launcher started; ``stop_all`` ends every one of them."""

    log_dir: Path
    children: list[Child] = field(default_factory=list)

    def start(self, name: str, args: list[str], nice: int = 0) -> Child:
        """Start ``python -m btrack ARGS``; ``nice`` > 0 puts its CPU priority that much
        below the launcher's own (for processes off the critical path, so they yield the
        cores when they are short)."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        log_path = self.log_dir / f"{name}.log"
        out_path = self.log_dir / f"{name}.out"
        with open(log_path, "wb") as err, open(out_path, "wb") as out:
            proc = subprocess.Popen(
                [sys.executable, "-m", "btrack", *args],
                stdin=subprocess.DEVNULL, stdout=out, stderr=err,
                start_new_session=True,  # Ctrl-C reaches the launcher only; it ends them
                env={**os.environ, "PYTHONUNBUFFERED": "1"},
            )
        if nice > 0:
            try:
                # below the launcher's own priority, whatever it was started at
                own = os.getpriority(os.PRIO_PROCESS, 0)
                os.setpriority(os.PRIO_PROCESS, proc.pid, min(19, own + nice))
            except OSError:
                pass  # it only costs speed
        child = Child(name, proc, log_path, out_path)
        self.children.append(child)
        # So that whoever started the launcher can end every child by pid, whatever happens.
        (self.log_dir / "pids.json").write_text(
            json.dumps({c.name: c.pid for c in self.children}, indent=1)
        )
        return child

    def stop(self, child: Child, grace_s: float = 5.0) -> int | None:
        if child.alive():
            try:
                os.kill(child.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
            try:
                child.proc.wait(grace_s)
            except subprocess.TimeoutExpired:
                os.kill(child.pid, signal.SIGKILL)
                child.proc.wait()
        return child.proc.returncode

    @contextlib.contextmanager
    def stopped_on_interrupt(self) -> Iterator[None]:
        """On Ctrl-C or SIGTERM inside the block, end every child before anything else
        unwinds (a session's close, which can wait on a loaded router), then go on
        with the interrupt."""
        try:
            yield
        except KeyboardInterrupt:
            self.stop_all()
            raise

    def stop_all(self, grace_s: float = 5.0) -> None:
        for child in self.children:
            if child.alive():
                try:
                    os.kill(child.pid, signal.SIGTERM)
                    os.kill(child.pid, signal.SIGCONT)  # a frozen child must wake to end
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + grace_s
        for child in self.children:
            try:
                child.proc.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.kill(child.pid, signal.SIGKILL)
                child.proc.wait()
