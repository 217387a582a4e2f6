"""Linux network namespaces as hosts, for the multi-host tests.

A ``Site`` is one lab: a namespace for the base station with a bridge, one namespace
per robot computer, each robot linked to the bridge through the link emulator
(``tests/linkemu.py``: delay and loss as netem would add, in both directions; a link
is cut by taking the robot's interface down), and a veth from the test's own
namespace to the base station, the operator's laptop, for the test's observer.
Everything it makes has a random suffix in its name, and ``close`` removes all of
it and ends every process it started, by pid, whatever happened before.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

from tests.procutil import end


def stop(proc: subprocess.Popen) -> None:
    """End a process we started, by pid, unless it has already exited and been
    reaped: its pid may then belong to someone else's process."""
    if proc.poll() is None:
        end(proc)

LINKEMU = Path(__file__).resolve().parent / "linkemu.py"


def spawn(ns: str, log: Path, argv: list[str], env: dict[str, str]
          ) -> subprocess.Popen[bytes]:
    """``argv`` inside namespace ``ns`` with exactly ``env``, its stderr in LOG.log and its
    stdout in LOG.out; ``ip netns exec`` execs, so the pid is the command's own."""
    log.parent.mkdir(parents=True, exist_ok=True)
    with open(log.with_name(log.name + ".log"), "wb") as err, \
            open(log.with_name(log.name + ".out"), "wb") as out:
        return subprocess.Popen(["ip", "netns", "exec", ns, *argv], stdin=subprocess.DEVNULL,
                                stdout=out, stderr=err, start_new_session=True, env=env)


class Observer:
    """The operator's laptop: a Zenoh session of configuration ``conf`` (tried again every
    0.2 s for ``wait_s`` while its router is not up yet) that hears the world's ticks
    and the agents' states of namespace ``ns``, each stamped with its wall clock:
    ``ticks`` as (wall, t, live ids), ``states`` as (wall, t, robot, lo, hi, lower,
    upper). ``close`` ends the session, waiting at most 3 s."""

    def __init__(self, conf: dict, ns: str, wait_s: float = 30.0):
        import zenoh

        from wire import AgentState, Keys, Tick, decode

        self.ticks: list[tuple[float, float, tuple[int, ...]]] = []
        self.states: list[tuple[float, float, int, float, float, int, int]] = []
        self.lock = threading.Lock()
        deadline = time.monotonic() + wait_s
        while True:
            try:
                self.session = zenoh.open(zenoh.Config.from_json5(json.dumps(conf)))
                break
            except zenoh.ZError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.2)

        def on_tick(s: zenoh.Sample) -> None:
            tick = decode(Tick, s.payload.to_bytes())
            with self.lock:
                self.ticks.append((time.monotonic(), tick.t, tuple(tick.live)))

        def on_state(s: zenoh.Sample) -> None:
            st = decode(AgentState, s.payload.to_bytes())
            with self.lock:
                self.states.append((time.monotonic(), st.t, st.robot, st.lo, st.hi,
                                    st.lower, st.upper))

        keys = Keys(ns)
        self._subs = [self.session.declare_subscriber(keys.world_tick(), on_tick),
                      self.session.declare_subscriber(keys.state("*"), on_state)]

    def last_t(self) -> float:
        """The simulated time of the last tick heard; -1 before the first."""
        with self.lock:
            return self.ticks[-1][1] if self.ticks else -1.0

    def close(self) -> None:
        closer = threading.Thread(target=self.session.close, daemon=True)
        closer.start()
        closer.join(3)


def _ip(*args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
    res = subprocess.run(["ip", *args], capture_output=True, text=True, timeout=30)
    if check and res.returncode != 0:
        raise RuntimeError(f"ip {' '.join(args)}: {res.stderr.strip()}")
    return res


def unavailable() -> str | None:
    """Why namespaces cannot be made here, or None if they can."""
    if os.geteuid() != 0:
        return "network namespaces need root (ip netns add)"
    if shutil.which("ip") is None:
        return "no ip command (iproute2)"
    if not os.path.exists("/dev/net/tun"):
        return "no /dev/net/tun for the link emulator"
    name = f"btprobe{uuid.uuid4().hex[:6]}"
    res = _ip("netns", "add", name, check=False)
    if res.returncode != 0:
        return f"ip netns add failed: {res.stderr.strip()}"
    _ip("netns", "del", name, check=False)
    return None


class Site:
    """Base station and robot computers in namespaces; see the module docstring."""

    def __init__(self, robots: int, logs: Path):
        tag = uuid.uuid4().hex[:6]
        self.tag = tag
        self.robots = robots
        self.logs = logs
        octet = int(tag[:2], 16) % 200 + 20  # a private /24 per site
        self.lan = f"10.213.{octet}"  # the robots' network: base .1, robot i .(10+i)
        self.mgmt = f"10.214.{octet}"  # the operator's veth: base .1, test side .2
        self.base_ns = f"bt{tag}b"
        self.robot_ns = [f"bt{tag}r{i}" for i in range(robots)]
        self.robot_if = [f"bt{tag}a{i}" for i in range(robots)]
        self.base_if = [f"bt{tag}c{i}" for i in range(robots)]
        self.veth = (f"bt{tag}o", f"bt{tag}p")
        self.procs: list[subprocess.Popen[bytes]] = []
        self.emu: subprocess.Popen[str] | None = None
        self.made_ns: list[str] = []

    @property
    def base_addr(self) -> str:
        return f"{self.lan}.1"

    @property
    def mgmt_addr(self) -> str:
        return f"{self.mgmt}.1"

    def up(self) -> None:
        for ns in (self.base_ns, *self.robot_ns):
            _ip("netns", "add", ns)
            self.made_ns.append(ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        b = self.base_ns
        _ip("-n", b, "link", "add", "br0", "type", "bridge")
        _ip("-n", b, "addr", "add", f"{self.base_addr}/24", "dev", "br0")
        _ip("-n", b, "link", "set", "br0", "up")
        pairs = [n for pair in zip(self.robot_if, self.base_if, strict=True) for n in pair]
        self.emu = subprocess.Popen([sys.executable, str(LINKEMU), *pairs],
                                    stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
                                    start_new_session=True)
        assert self.emu.stdout is not None
        if self.emu.stdout.readline().strip() != "ready":
            raise RuntimeError("the link emulator did not start")
        for i, ns in enumerate(self.robot_ns):
            _ip("link", "set", self.robot_if[i], "netns", ns)
            _ip("link", "set", self.base_if[i], "netns", b)
            _ip("-n", b, "link", "set", self.base_if[i], "master", "br0")
            _ip("-n", b, "link", "set", self.base_if[i], "up")
            _ip("-n", ns, "addr", "add", f"{self.lan}.{10 + i}/24", "dev", self.robot_if[i])
            _ip("-n", ns, "link", "set", self.robot_if[i], "up")
        o, p = self.veth
        _ip("link", "add", o, "type", "veth", "peer", "name", p)
        _ip("link", "set", p, "netns", b)
        _ip("addr", "add", f"{self.mgmt}.2/24", "dev", o)
        _ip("link", "set", o, "up")
        _ip("-n", b, "addr", "add", f"{self.mgmt_addr}/24", "dev", p)
        _ip("-n", b, "link", "set", p, "up")

    def impair(self, delay_ms: float, loss: float) -> None:
        """Delay and loss on every robot link, each way."""
        assert self.emu is not None and self.emu.stdin and self.emu.stdout
        self.emu.stdin.write(f"set {delay_ms} {loss}\n")
        self.emu.stdin.flush()
        assert self.emu.stdout.readline().strip() == "ok"

    def link(self, robot: int, up: bool) -> None:
        """Cut (or restore) robot ``robot``'s link, at its own interface."""
        _ip("-n", self.robot_ns[robot], "link", "set", self.robot_if[robot],
            "up" if up else "down")

    def start(self, ns: str, name: str, args: list[str]) -> subprocess.Popen[bytes]:
        """``btrack ARGS`` inside namespace ``ns``; ``ip netns exec`` execs, so the pid
        is the Python process's own."""
        return self.run(ns, name, [sys.executable, "-m", "btrack", *args],
                        {**os.environ, "PYTHONUNBUFFERED": "1"})

    def run(self, ns: str, name: str, argv: list[str], env: dict[str, str]
            ) -> subprocess.Popen[bytes]:
        """The command line ``argv`` inside namespace ``ns`` with exactly the environment
        ``env`` (as systemd gives a unit its own), its output in the logs; ended by
        ``close`` unless the caller has ended it before."""
        proc = spawn(ns, self.logs / name, argv, env)
        self.procs.append(proc)
        return proc

    def close(self) -> None:
        for proc in reversed(self.procs):
            stop(proc)
        if self.emu is not None:
            stop(self.emu)
        _ip("link", "del", self.veth[0], check=False)
        for ns in self.made_ns:
            _ip("netns", "del", ns, check=False)


class Mesh:
    """Hosts on one switch, for a mesh of routers: ``hosts`` namespaces, each linked by a
    veth to a bridge in a namespace of its own (the switch), host k at LAN address
    ``addr(k)``, and a veth from the caller's namespace to the switch (``observer_addr``)
    for an observer. No link emulator: the links are the kernel's, so a hundred
    processes on them cost nothing more than on loopback. ``close`` removes everything
    it made and ends every process it started, by pid."""

    def __init__(self, hosts: int, logs: Path):
        tag = uuid.uuid4().hex[:6]
        self.hosts, self.logs = hosts, logs
        self.lan = f"10.215.{int(tag[:2], 16) % 200 + 20}"
        self.switch_ns = f"bt{tag}s"
        self.host_ns = [f"bt{tag}h{k}" for k in range(hosts)]
        self.observer_if = (f"bt{tag}o", f"bt{tag}p")
        self.procs: list[subprocess.Popen[bytes]] = []
        self.made_ns: list[str] = []

    def addr(self, k: int) -> str:
        return f"{self.lan}.{10 + k}"

    @property
    def observer_addr(self) -> str:
        return f"{self.lan}.2"

    def up(self) -> None:
        for ns in (self.switch_ns, *self.host_ns):
            _ip("netns", "add", ns)
            self.made_ns.append(ns)
            _ip("-n", ns, "link", "set", "lo", "up")
        s = self.switch_ns
        _ip("-n", s, "link", "add", "br0", "type", "bridge")
        _ip("-n", s, "link", "set", "br0", "up")
        for k, ns in enumerate(self.host_ns):
            inner, outer = f"{self.switch_ns}{k}a", f"{self.switch_ns}{k}b"
            _ip("-n", ns, "link", "add", inner, "type", "veth", "peer", "name", outer,
                "netns", s)
            _ip("-n", s, "link", "set", outer, "master", "br0")
            _ip("-n", s, "link", "set", outer, "up")
            _ip("-n", ns, "addr", "add", f"{self.addr(k)}/24", "dev", inner)
            _ip("-n", ns, "link", "set", inner, "up")
        o, p = self.observer_if
        _ip("link", "add", o, "type", "veth", "peer", "name", p, "netns", s)
        _ip("-n", s, "link", "set", p, "master", "br0")
        _ip("-n", s, "link", "set", p, "up")
        _ip("addr", "add", f"{self.observer_addr}/24", "dev", o)
        _ip("link", "set", o, "up")

    def start(self, k: int, name: str, args: list[str]) -> subprocess.Popen[bytes]:
        """``btrack ARGS`` on host ``k``, its output in the logs."""
        proc = spawn(self.host_ns[k], self.logs / name, [sys.executable, "-m", "btrack", *args],
                     {**os.environ, "PYTHONUNBUFFERED": "1"})
        self.procs.append(proc)
        return proc

    def close(self) -> None:
        for proc in reversed(self.procs):
            stop(proc)
        _ip("link", "del", self.observer_if[0], check=False)
        for ns in self.made_ns:
            _ip("netns", "del", ns, check=False)
