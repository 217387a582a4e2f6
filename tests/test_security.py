"""The rendered TLS and access-control configuration, for real: a router process
(``btrack router`` with the router's JSON5), a process holding robot 2's certificate,
and this test's session as the base station's observer, all on loopback.

- A process without a valid certificate (none, one from another CA even with robot 1's
  name, plain TCP) cannot join: it fails to open and nothing of it reaches anyone.
- Robot 2's certificate cannot publish robot 1's command or state, nor hold robot 1's
  liveliness token; the same process's own keys go through (the control).
- Every base station process has a certificate of its own, and a team (world,
  localizer, recorder, agents) runs on the rights each is given and no more.
- With hardware, the rendered units' own commands run (router, laser bridge, robot
  0's Create bridge, against emulated devices on pseudo-terminals): robot 0's
  certificate puts its robot's sensing and hears its commands, and cannot do either
  for robot 1.
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import zenoh

from deploy.certs import make_ca, make_cert, make_fleet_certs
from deploy.fleet import Fleet, parse
from deploy.render import client_config, render, router_config
from hwbridge.create import model as cm
from hwbridge.emulators.pty import CreateEmulator, LmsEmulator
from tests.netns import stop
from tests.procutil import free_port, start, unique_ns, wait_for
from tests.unitfiles import exec_argv, host_files
from wire import Cmd, Keys, encode

ROOT = Path(__file__).resolve().parent.parent
PROBE = ROOT / "tests" / "acl_probe.py"

pytestmark = pytest.mark.skipif(
    subprocess.run(["which", "openssl"], capture_output=True).returncode != 0,
    reason="needs the openssl command to make test certificates")


class Bus:
    """The team's setup: certificates, configuration files and the router process."""

    def __init__(self, tmp: Path, acl: bool = True, robots: int = 3, base: str = ""):
        self.tmp = tmp
        self.ns = unique_ns()
        port = free_port()
        self.fleet: Fleet = parse(f'''
namespace = "{self.ns}"
[base]
host = "localhost"
address = "127.0.0.1"
port = {port}
{base}
[tls]
dir = "{tmp / "tls"}"
{"".join(f'[[robots]]{chr(10)}id = {i}{chr(10)}host = "localhost"{chr(10)}' for i in range(robots))}
''')
        make_fleet_certs(self.fleet, tmp / "tls", flat=True)
        conf = router_config(self.fleet, "127.0.0.1")
        if not acl:
            del conf["access_control"]
        self.router_file = self.write("router", conf)
        self.proc = start(["router", "--zenoh-config", str(self.router_file)],
                          log=tmp / "router.log")

    def write(self, name: str, conf: dict) -> Path:
        path = self.tmp / f"{name}.json5"
        path.write_text(json.dumps(conf, indent=1))
        return path

    def robot_config(self, rid: int) -> dict:
        return client_config(self.fleet, self.fleet.robot(rid), host="localhost")

    def probe(self, conf: dict, name: str, claim: int, own: int | None = None,
              ) -> subprocess.CompletedProcess[str]:
        path = self.write(name, conf)
        args = [sys.executable, str(PROBE), str(path), "--ns", self.ns, "--claim", str(claim)]
        if own is not None:
            args += ["--own", str(own)]
        proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                text=True, start_new_session=True)
        try:
            out, _ = proc.communicate(timeout=60)
        finally:
            stop(proc)
        return subprocess.CompletedProcess(args, proc.returncode, out, "")


class Observer:
    """Everything under the namespace that reaches the base station, by key."""

    def __init__(self, session: zenoh.Session, ns: str):
        self.lock = threading.Lock()
        self.keys: list[str] = []
        self.tokens: list[str] = []
        self._subs = [
            session.declare_subscriber(f"{ns}/**", self._on_put),
            session.liveliness().declare_subscriber(f"{ns}/alive/agent/*", self._on_token),
        ]

    def _on_put(self, sample: zenoh.Sample) -> None:
        with self.lock:
            self.keys.append(str(sample.key_expr))

    def _on_token(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            with self.lock:
                self.tokens.append(str(sample.key_expr))

    def seen(self, fragment: str) -> int:
        with self.lock:
            return sum(fragment in k for k in self.keys + self.tokens)


def open_observer(b: Bus) -> tuple[zenoh.Session, Observer]:
    """The base station's session, once the router accepts it."""
    conf = client_config(b.fleet, "recorder")  # it hears everything, and puts nothing
    opened: list[zenoh.Session] = []

    def base_station_joins() -> bool:
        assert b.proc.poll() is None, (b.tmp / "router.log").read_text()
        try:
            opened.append(zenoh.open(zenoh.Config.from_json5(json.dumps(conf))))
        except zenoh.ZError:
            return False
        return True

    wait_for(base_station_joins, 30, "the router to accept the base station")
    return opened[0], Observer(opened[0], b.ns)


@pytest.fixture(scope="module")
def bus(tmp_path_factory):
    b = Bus(tmp_path_factory.mktemp("sec"))
    try:
        session, observer = open_observer(b)
        with session:
            yield b, observer
    finally:
        stop(b.proc)


def test_robot2_certificate_cannot_publish_robot1_keys(bus) -> None:
    b, obs = bus
    res = b.probe(b.robot_config(2), "robot2", claim=1, own=2)
    assert res.returncode == 0 and "opened" in res.stdout, res.stdout
    # the control: robot 2's own keys went through, the last round included
    wait_for(lambda: obs.seen(f"{b.ns}/robot/2/cmd") >= 20, 10, "robot 2's own commands")
    wait_for(lambda: obs.seen(f"{b.ns}/agent/2/state") >= 20, 10, "robot 2's own states")
    wait_for(lambda: obs.seen(f"{b.ns}/alive/agent/2") >= 1, 10, "robot 2's own token")
    # every claim on robot 1 was sent before robot 2's own of the same round: none arrived
    assert obs.seen(f"{b.ns}/robot/1/") == 0
    assert obs.seen(f"{b.ns}/agent/1/") == 0
    assert obs.seen(f"{b.ns}/alive/agent/1") == 0
    assert "robot/1" not in " ".join(obs.keys + obs.tokens)


def test_a_process_without_a_valid_certificate_cannot_join(bus, tmp_path: Path) -> None:
    b, obs = bus
    robot1 = b.robot_config(1)
    no_cert = json.loads(json.dumps(robot1))
    tls = no_cert["transport"]["link"]["tls"]
    del tls["connect_certificate"], tls["connect_private_key"]
    # a certificate with robot 1's very name, from a CA the router does not trust
    rogue_ca = make_ca(tmp_path / "rogue", "rogue CA")
    make_cert(rogue_ca, tmp_path / "rogue1.pem", tmp_path / "rogue1.key",
              Fleet.common_name(1), ("localhost",))
    rogue = json.loads(json.dumps(robot1))
    rogue["transport"]["link"]["tls"].update(connect_certificate=str(tmp_path / "rogue1.pem"),
                                             connect_private_key=str(tmp_path / "rogue1.key"))
    plain = json.loads(json.dumps(robot1))
    plain["connect"]["endpoints"] = [e.replace("tls/", "tcp/") for e in
                                     plain["connect"]["endpoints"]]
    for name, conf in (("no-cert", no_cert), ("rogue-ca", rogue), ("plain-tcp", plain)):
        res = b.probe(conf, name, claim=1)
        assert res.returncode == 3 and "cannot open" in res.stdout, (name, res.stdout)
    assert obs.seen(f"{b.ns}/robot/1/") == 0 and obs.seen(f"{b.ns}/alive/agent/1") == 0
    # and the router still serves a robot with a good certificate
    res = b.probe(b.robot_config(0), "robot0", claim=2, own=0)
    assert res.returncode == 0
    wait_for(lambda: obs.seen(f"{b.ns}/robot/0/cmd") >= 20, 10, "robot 0's own commands")
    assert obs.seen(f"{b.ns}/robot/2/cmd") == 20  # only robot 2's own, from the first test


def test_without_access_control_the_same_claim_would_go_through(tmp_path: Path) -> None:
    """The control for the first test: it is the access control, not the setup, that
    stops robot 2's claim on robot 1's keys."""
    b = Bus(tmp_path, acl=False)
    try:
        session, obs = open_observer(b)
        with session:
            res = b.probe(b.robot_config(2), "robot2", claim=1, own=2)
            assert res.returncode == 0, res.stdout
            wait_for(lambda: obs.seen(f"{b.ns}/robot/2/cmd") >= 20, 10, "robot 2's commands")
            assert obs.seen(f"{b.ns}/robot/1/cmd") == 20
            assert obs.seen(f"{b.ns}/alive/agent/1") == 1
    finally:
        stop(b.proc)


def test_a_team_runs_on_the_rights_each_process_is_given(tmp_path: Path) -> None:
    """World, localizer, recorder and an agent, each with its own certificate and
    nothing but its own rights: every tick's scan, sensing, pose (the localizer's),
    state and command reach the recording. (Agents hearing each other is
    test_netns's.)"""
    b = Bus(tmp_path, robots=1, base="localizer = true")
    fleet, ns = b.fleet, ["--ns", b.ns]
    procs = []
    try:
        def conf(name: str, who) -> str:
            return str(b.write(name, client_config(fleet, who, host="localhost")))

        procs.append(start(["record", "--out", str(tmp_path / "run"), "--zenoh-config",
                            conf("recorder", "recorder"), *ns], log=tmp_path / "recorder.log"))
        procs.append(start(["localizer", "--robots", "1", "--zenoh-config",
                            conf("localizer", "localizer"), *ns], log=tmp_path / "loc.log"))
        procs.append(start(["agent", "--id", "0", "--robots", "1", "--zenoh-config",
                            conf("agent0", fleet.robot(0)), *ns], log=tmp_path / "agent0.log"))
        world = start(["world", "--robots", "1", "--localization", "pf", "--duration", "1",
                       "--wait-recorder", "--zenoh-config", conf("world", "world"), *ns],
                      log=tmp_path / "world.log")
        procs.append(world)
        assert world.wait(120) == 0, (tmp_path / "world.log").read_text()[-2000:]
        assert procs[0].wait(30) == 0, (tmp_path / "recorder.log").read_text()[-2000:]
    finally:
        for proc in procs:
            stop(proc)
        stop(b.proc)
    counts = topic_counts(tmp_path / "run" / "run.mcap")
    ticks = counts["world/tick"]
    assert ticks == 10, counts
    for topic in ("laser/scan", "world/truth", "robot/0/sense", "robot/0/pose",
                  "agent/0/state", "robot/0/cmd"):
        assert counts[topic] == ticks, (topic, counts)


def topic_counts(path: Path) -> dict[str, int]:
    from collections import Counter

    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return Counter(ch.topic for _, ch, _ in make_reader(f).iter_messages())


def test_hardware_bridges_run_as_rendered_and_a_robot_bridges_only_its_own_robot(
        tmp_path: Path) -> None:
    """Issue 19, item 9: the base station's btrack-hwbridge.service ran `btrack
    hwbridge`, no command; robot I's certificate could neither put robot/I/sense nor hear
    robot/I/cmd. Here a hardware fleet is rendered (its files in this test's directory),
    and the commands of its units run as systemd would run them: the router, the laser
    bridge, and robot 0's Create bridge; a second bridge on robot 0's computer, with
    robot 0's certificate, claims robot 1."""
    ns, port = unique_ns(), free_port()
    conf, venv_btrack = tmp_path / "etc", Path(sys.executable).parent / "btrack"
    fleet = parse(f'''
namespace = "{ns}"
btrack = "{venv_btrack}"
config_dir = "{conf}"
epoch = {time.time() - 60:.0f}
[base]
host = "localhost"
port = {port}
world = "hardware"
laser_port = "{tmp_path / "lms"}"
world_args = ["--baud", "38400"]
[tls]
dir = "{conf / "tls"}"
[[robots]]
id = 0
host = "localhost"
port = "{tmp_path / "create0"}"
[[robots]]
id = 1
host = "localhost"
''')
    files = render(fleet)
    for name, text in host_files(files, "localhost").items():
        path = Path(name)
        if path.is_relative_to(conf):  # this host's configuration, under the test's directory
            path.parent.mkdir(parents=True, exist_ok=True)
            # the router listens on loopback only (the rendered one on every interface)
            path.write_text(text.replace("0.0.0.0", "127.0.0.1"))
    make_fleet_certs(fleet, conf / "tls", flat=True)
    creates = {i: CreateEmulator(tmp_path / f"create{i}", cm.MODELS["create"]).start()
               for i in (0, 1)}
    lms = LmsEmulator(tmp_path / "lms", lambda: [3.0] * 361).start()
    keys, procs = Keys(ns), {}

    def run(name: str, argv: list[str]) -> None:
        procs[name] = subprocess.Popen(argv, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                                       stderr=open(tmp_path / f"{name}.log", "wb"),  # noqa: SIM115
                                       start_new_session=True)

    try:
        router = exec_argv(files, "localhost", "btrack-router.service")
        assert router[:2] == [str(venv_btrack), "router"], router
        run("router", router)
        laser = exec_argv(files, "localhost", "btrack-hwbridge.service")
        assert laser[1:3] == ["bridge", "lms"], laser
        bridge = exec_argv(files, "localhost", "btrack-bridge@.service", "0")
        assert bridge[1:3] == ["bridge", "create"] and "--epoch" in bridge, bridge
        # The bridge's session comes from ZENOH_CONFIG in agent-0.env, robot 0's identity.
        env = {"ZENOH_CONFIG": str(conf / "zenoh-agent-0.json5"), "PATH": "/usr/bin:/bin"}
        b = Bus.__new__(Bus)  # the observer's helpers, on this fleet's router
        b.tmp, b.ns, b.fleet, b.proc = tmp_path, ns, fleet, procs["router"]
        session, obs = open_observer(b)
        with session:
            run("laser", laser)
            procs["bridge0"] = subprocess.Popen(
                bridge, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=open(tmp_path / "bridge0.log", "wb"), start_new_session=True)  # noqa: SIM115
            claim = [*bridge]
            claim[claim.index("--id") + 1] = "1"
            claim[claim.index("--port") + 1] = creates[1].path
            procs["claim1"] = subprocess.Popen(
                claim, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                stderr=open(tmp_path / "claim1.log", "wb"), start_new_session=True)  # noqa: SIM115
            # each robot's agent (its own certificate) commands its robot
            agents = {i: zenoh.open(zenoh.Config.from_json5(json.dumps(client_config(
                fleet, fleet.robot(i), host="localhost")))) for i in (0, 1)}
            try:
                wait_for(lambda: obs.seen(keys.sense(0)) >= 10, 30, "robot 0's sensing")
                wait_for(lambda: obs.seen(keys.scan()) >= 2, 30, "the laser's scans")
                assert procs["claim1"].poll() is None, (tmp_path / "claim1.log").read_text()
                for k in range(20):  # robot 1's first: when robot 0's are all in, so are they
                    for i in (1, 0):
                        agents[i].put(keys.cmd(i), encode(Cmd(k * 0.1, k, i, 0.25, 0.0)))
                    time.sleep(0.02)
                wait_for(lambda: creates[0].device.wheel_speeds() == (0.25, 0.25), 10,
                         "robot 0's wheels driven by its commands")
                time.sleep(0.3)
            finally:
                for s in agents.values():
                    s.close()
            for name in ("bridge0", "claim1"):
                stop(procs[name])
            summary = {n: json.loads(procs[n].stdout.read().decode().strip().splitlines()[-1])
                       for n in ("bridge0", "claim1")}
            assert summary["bridge0"]["cmds"] == 20, summary
            assert summary["claim1"]["sense"] >= 10, summary  # it did put, nothing arrived
            assert obs.seen(keys.sense(1)) == 0
            assert summary["claim1"]["cmds"] == 0 and summary["claim1"]["dropped"] == 0, summary
    finally:
        for proc in procs.values():
            stop(proc)
        for emu in (*creates.values(), lms):
            emu.stop()
