"""The rendered TLS and access-control configuration, for real: a router process
(``btrack router`` with the router's JSON5), a process holding robot 2's certificate,
and this test's session as the base station's observer, all on loopback.

- A process without a valid certificate (none, one from another CA even with robot 1's
  name, plain TCP) cannot join: it fails to open and nothing of it reaches anyone.
- Robot 2's certificate cannot publish robot 1's command or state, nor hold robot 1's
  liveliness token; the same process's own keys go through (the control).
- Robot 2's certificate in a hostile process (tests/acl_attacker.py) can put, delete,
  hold, hear, watch, query and answer nothing of any key class but its own: every key of
  the wire contract, the namespace's and everything's wildcards, another team's keys;
  the rules as written say the same for every robot, and give each base station
  process only its own keys. The router listens with mutual TLS only.
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
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest
import zenoh

from deploy.certs import make_ca, make_cert, make_fleet_certs
from deploy.fleet import Fleet, parse
from deploy.render import client_config, render, router_config
from hwbridge.create import model as cm
from hwbridge.emulators.pty import CreateEmulator, LmsEmulator
from tests.netns import stop
from tests.procutil import free_port, open_when_accepted, start, unique_ns, wait_for
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
        else:
            add_test_observer(conf, tmp / "tls")
        self.router_conf = conf
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


WATCHER_CN = "btrack-test-watcher"


def add_test_observer(conf: dict, tls: Path) -> None:
    """A subject of the tests' own, with every right everywhere (so that it can put,
    hear, query and answer wherever a robot must not), and its certificate. It changes
    no one else's rights."""
    acl = conf["access_control"]
    acl["rules"].append({"id": "watcher-all", "permission": "allow",
                         "flows": ["ingress", "egress"],
                         "messages": ["put", "delete", "declare_subscriber", "query",
                                      "declare_queryable", "reply", "liveliness_token",
                                      "declare_liveliness_subscriber", "liveliness_query"],
                         "key_exprs": ["**"]})
    acl["subjects"].append({"id": "watcher", "cert_common_names": [WATCHER_CN]})
    acl["policies"].append({"id": "watcher", "rules": ["watcher-all"], "subjects": ["watcher"]})
    make_cert((tls / "ca" / "ca.pem", tls / "ca" / "ca.key"), tls / "watcher.pem",
              tls / "watcher.key", WATCHER_CN)


class Observer:
    """Everything under the namespace that reaches the base station, by key."""

    def __init__(self, session: zenoh.Session, ns: str):
        self.session = session
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

    def hear_times(self, key: str, into: list[float]) -> zenoh.Subscriber:
        """Record the wall time every put on ``key`` arrives (until undeclared)."""
        return self.session.declare_subscriber(key, lambda s: into.append(time.time()))

    def seen(self, fragment: str) -> int:
        with self.lock:
            return sum(fragment in k for k in self.keys + self.tokens)


def open_observer(b: Bus) -> tuple[zenoh.Session, Observer]:
    """The base station's session, once the router accepts it."""
    conf = client_config(b.fleet, "recorder")  # it hears everything, and puts nothing
    session = open_when_accepted(conf, b.proc, b.tmp / "router.log", 30,
                                 "the router to accept the base station")
    return session, Observer(session, b.ns)


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


def test_a_link_ends_when_its_certificate_expires(bus, tmp_path: Path) -> None:
    """Issue 19, item 8: a certificate that expired while its link was up kept the link
    (78 puts after expiry, the last 39.6 s after). Robot 1 with a certificate valid for
    2 to 3 s more (to the second) puts its command every 20 ms and goes on 1.6 s past
    the expiry: what reaches the base station stops within 1 s of it, and the
    certificate opens no new link."""
    b, obs = bus
    ca = (b.tmp / "tls" / "ca" / "ca.pem", b.tmp / "tls" / "ca" / "ca.key")
    expires = (datetime.now(UTC) + timedelta(seconds=3)).replace(microsecond=0)
    assert (expires - datetime.now(UTC)).total_seconds() > 2
    make_cert(ca, tmp_path / "short.pem", tmp_path / "short.key", Fleet.common_name(1),
              ("localhost",), not_after=expires)
    conf = b.robot_config(1)
    conf["transport"]["link"]["tls"].update(connect_certificate=str(tmp_path / "short.pem"),
                                            connect_private_key=str(tmp_path / "short.key"))
    key = Keys(b.ns).cmd(1)
    arrived: list[float] = []
    watch = obs.hear_times(key, arrived)
    sent_after = 0
    with zenoh.open(zenoh.Config.from_json5(json.dumps(conf))) as robot:
        end = expires.timestamp() + 1.6
        while time.time() < end:
            robot.put(key, encode(Cmd(0.0, 0, 1, 0.0, 0.0)))
            sent_after += time.time() > expires.timestamp()
            time.sleep(0.02)
    watch.undeclare()
    assert sent_after > 30
    assert arrived and arrived[0] < expires.timestamp(), "none arrived while it was valid"
    assert max(arrived) < expires.timestamp() + 1.0, (max(arrived) - expires.timestamp())
    res = b.probe(conf, "expired", claim=1)
    assert res.returncode == 3 and "cannot open" in res.stdout, res.stdout


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


# --- every key class a robot must not put, hear, query or answer (issue 19, item 11) --

OTHER_NS = "elsewhere/team"  # another team's namespace on the same router


def forbidden(ns: str, rid: int, team: int) -> dict[str, list[str]]:
    """What robot ``rid`` of a simulated team must not do, by kind: keys it must not put
    (or delete), tokens it must not hold, keys it must not hear, queries it must not
    make (or answer): every key of the wire contract but its own, the namespace's and
    everything's wildcards, and another team's keys."""
    k, others = Keys(ns), [j for j in range(team) if j != rid]
    robots_of_others = [key for j in others for key in (k.sense(j), k.pose(j), k.cmd(j))]
    world = [k.scan(), k.truth(), k.world_tick(), k.world_info(), k.fault(), k.progress()]
    return {
        "put": [*robots_of_others, k.sense(rid), k.pose(rid), *(k.state(j) for j in others),
                *world, k.alive(rid), f"{OTHER_NS}/robot/{rid}/cmd", f"{ns}/anything"],
        "delete": [k.state(j) for j in others] + [k.cmd(others[0])],
        "tokens": [*(k.alive(j) for j in others), k.alive_recorder(), k.alive_localizer(),
                   f"{OTHER_NS}/alive/agent/{rid}"],
        "hear": [*robots_of_others, k.cmd(rid), *world, f"{OTHER_NS}/robot/{rid}/sense"],
        "subscribe": [f"{ns}/**", "**", f"{ns}/robot/*/sense", f"{ns}/world/**"],
        "watch": [f"{ns}/alive/**", k.alive_recorder(), k.alive_localizer()],
        "query": [k.progress(), k.sense(others[0]), f"{ns}/**", f"{OTHER_NS}/x"],
        "answer": [f"{ns}/robot/{rid}/answer", k.progress(), f"{ns}/**"],
    }


def may(acl: dict, subject: str, flow: str, message: str, key: str) -> bool:
    """Whether the access control lets ``subject`` send (ingress) or be sent (egress)
    ``message`` on ``key``: some rule of its policies allows it on a key expression
    that includes ``key`` (every rule here allows; the default denies)."""
    rules = {r["id"]: r for r in acl["rules"]}
    assert acl["default_permission"] == "deny"
    mine = [rules[rid] for p in acl["policies"] if subject in p["subjects"] for rid in p["rules"]]
    return any(r["permission"] == "allow" and flow in r["flows"] and message in r["messages"]
               and any(zenoh.KeyExpr(e).includes(zenoh.KeyExpr(key)) for e in r["key_exprs"])
               for r in mine)


def test_the_rendered_rules_forbid_a_robot_every_key_class_but_its_own(bus) -> None:
    """The rules as written (no router): for every robot, every forbidden kind and key;
    and the same rules let it do its own work (so the reading of the rules is right)."""
    b, _ = bus
    acl, ns = b.router_conf["access_control"], b.ns
    k = Keys(ns)
    for rid in range(b.fleet.team):
        me, bad = f"robot{rid}", forbidden(ns, rid, b.fleet.team)
        checks = [("ingress", "put", bad["put"]), ("ingress", "delete", bad["delete"]),
                  ("ingress", "liveliness_token", bad["tokens"]),
                  ("egress", "put", bad["hear"]),
                  ("ingress", "declare_subscriber", bad["hear"] + bad["subscribe"]),
                  ("ingress", "declare_liveliness_subscriber", bad["watch"]),
                  ("egress", "liveliness_token", bad["watch"][1:]),
                  ("ingress", "query", bad["query"]),
                  ("ingress", "liveliness_query", bad["watch"]),
                  ("ingress", "declare_queryable", bad["answer"]),
                  ("ingress", "reply", bad["answer"] + bad["query"]),
                  ("egress", "query", bad["answer"] + bad["query"])]
        for flow, message, keys in checks:
            allowed = [key for key in keys if may(acl, me, flow, message, key)]
            assert not allowed, (me, flow, message, allowed)
        own = [("ingress", "put", k.cmd(rid)), ("ingress", "put", k.state(rid)),
               ("ingress", "liveliness_token", k.alive(rid)), ("egress", "put", k.sense(rid)),
               ("egress", "put", k.pose(rid)), ("egress", "put", k.state((rid + 1) % 3)),
               ("ingress", "declare_subscriber", k.state("*")),
               ("ingress", "declare_liveliness_subscriber", k.alive("*"))]
        assert all(may(acl, me, *x) for x in own), me


def test_each_base_station_process_may_put_and_hear_only_its_own_keys(bus) -> None:
    """The rules as written, for the base station's processes: over every key of the
    wire contract, what each may put and be sent is exactly what it needs."""
    b, _ = bus
    acl, k, n = b.router_conf["access_control"], Keys(b.ns), b.fleet.team
    every = [*(key for i in range(n) for key in (k.sense(i), k.pose(i), k.cmd(i),
                                                   k.state(i), k.alive(i))),
             k.scan(), k.truth(), k.world_tick(), k.world_info(), k.fault(), k.progress(),
             k.alive_recorder(), k.alive_localizer()]

    def rights(subject: str, flow: str, message: str) -> set[str]:
        return {key for key in every if may(acl, subject, flow, message, key)}

    robots = range(n)
    assert rights("world", "ingress", "put") == {
        *(k.sense(i) for i in robots), k.scan(), k.truth(), k.world_tick(), k.world_info()}
    assert rights("world", "egress", "put") == {k.cmd(i) for i in robots}
    assert rights("recorder", "ingress", "put") == set()
    assert rights("recorder", "egress", "put") == set(every)  # it hears everything
    assert rights("recorder", "ingress", "declare_queryable") == {k.progress()}
    for role in ("world", "recorder"):
        assert rights(role, "ingress", "query") == set()
    assert rights("world", "ingress", "liveliness_token") == set()
    assert rights("recorder", "ingress", "liveliness_token") == {k.alive_recorder()}


def test_the_router_listens_with_mutual_tls_only(bus) -> None:
    """Every endpoint the router listens on is TLS with client certificates; a plain
    session to each is refused (a plain-TCP listener would let anyone in)."""
    b, _ = bus
    conf = b.router_conf
    assert conf["transport"]["link"]["tls"]["enable_mtls"] is True
    endpoints = conf["listen"]["endpoints"]
    assert endpoints and all(e.startswith("tls/") for e in endpoints), endpoints
    for e in endpoints:
        plain = b.robot_config(0)
        del plain["transport"]["link"]["tls"]
        plain["connect"]["endpoints"] = ["tcp/" + e.split("/", 1)[1]]
        res = b.probe(plain, "plain", claim=0)
        assert res.returncode == 3 and "cannot open" in res.stdout, (e, res.stdout)


class Watcher:
    """The tests' own subject on the router: hears everything, answers some queries,
    and counts what came from the attacker (its payloads are marked)."""

    def __init__(self, b: Bus, answer: list[str]):
        conf = client_config(b.fleet, "recorder")
        tls = conf["transport"]["link"]["tls"]
        tls.update(connect_certificate=str(b.tmp / "tls" / "watcher.pem"),
                   connect_private_key=str(b.tmp / "tls" / "watcher.key"))
        self.lock = threading.Lock()
        self.puts: list[str] = []
        self.tokens: list[tuple[float, str]] = []
        self.queries: list[str] = []
        self.hear = zenoh.open(zenoh.Config.from_json5(json.dumps(conf)))
        self.speak = zenoh.open(zenoh.Config.from_json5(json.dumps(conf)))
        self._keep = [
            self.hear.declare_subscriber("**", self._on_put),
            self.hear.liveliness().declare_subscriber("**", self._on_token),
            *(self.hear.declare_queryable(k, self._on_query) for k in answer)]

    def _on_put(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.DELETE or \
                sample.payload.to_bytes().startswith(b"attacker"):
            with self.lock:
                self.puts.append(str(sample.key_expr))

    def _on_token(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            with self.lock:
                self.tokens.append((time.monotonic(), str(sample.key_expr)))

    def _on_query(self, query: zenoh.Query) -> None:
        payload = query.payload.to_bytes() if query.payload is not None else b""
        if payload.startswith(b"attacker"):
            with self.lock:
                self.queries.append(str(query.key_expr))
        query.reply(query.key_expr, b"watcher")

    def close(self) -> None:
        for s in (self.hear, self.speak):
            s.close()


def test_a_robot_can_put_hear_query_or_answer_nothing_of_any_other_key_class(bus) -> None:
    """Robot 2's certificate in a hostile process (tests/acl_attacker.py) tries every
    kind and key of ``forbidden`` through the router; each attempt comes before a
    control of the same kind that goes through, so that none arriving means none was
    let through."""
    b, _ = bus
    ns, rid, k = b.ns, 2, Keys(b.ns)
    bad = forbidden(ns, rid, b.fleet.team)
    plan = {"subscribe": bad["hear"] + bad["subscribe"], "may_subscribe": [k.state("*")],
            "watch": bad["watch"], "may_watch": [k.alive("*")],
            "answer": bad["answer"], "control_hear": k.sense(rid), "tokens": bad["tokens"],
            "put": bad["put"], "delete": bad["delete"], "query": bad["query"],
            "control_token": k.alive(rid), "control_put": [k.cmd(rid), k.state(rid)]}
    (b.tmp / "plan.json").write_text(json.dumps(plan))
    config = b.write("attacker", b.robot_config(rid))
    # the watcher answers where it may be asked (concrete keys: a wildcard queryable of
    # its own would match the attacker's queryables below)
    w = Watcher(b, answer=[q for q in bad["query"] if "*" not in q])
    tokens = [w.speak.liveliness().declare_token(key)  # what it must not see, and may
              for key in (k.alive_recorder(), k.alive_localizer(), k.alive(0))]
    proc = subprocess.Popen([sys.executable, str(ROOT / "tests" / "acl_attacker.py"),
                             str(config), str(b.tmp / "plan.json")], stdin=subprocess.PIPE,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            start_new_session=True)
    lines: list[str] = []

    def read_until(word: str, timeout: float) -> None:
        reader = threading.Thread(target=lambda: lines.extend(
            iter(lambda: proc.stdout.readline().strip() or "EOF", word)), daemon=True)
        reader.start()
        reader.join(timeout)
        assert not reader.is_alive() and "EOF" not in lines, (word, lines)

    try:
        read_until("ready", 30)
        # every key it must not hear, then the control, round after round until it has
        # heard the control a few times: each round's forbidden puts came first
        heard_it = threading.Event()
        reader = threading.Thread(target=lambda: (read_until("heard", 30), heard_it.set()),
                                  daemon=True)
        reader.start()
        while not heard_it.is_set() and reader.is_alive():
            for key in bad["hear"]:
                w.speak.put(key, b"watcher")
            w.speak.put(k.state(0), b"watcher")
            w.speak.put(k.sense(rid), b"watcher")
            time.sleep(0.02)
        assert heard_it.is_set(), lines
        for token in tokens:
            token.undeclare()
        went = time.monotonic()
        proc.stdin.write("go\n")
        proc.stdin.flush()
        read_until("done", 30)
        report = json.loads(lines[-1])
        # what it put, deleted, held or asked: only its own control arrived
        wait_for(lambda: w.puts.count(k.cmd(rid)) >= 5 and w.puts.count(k.state(rid)) >= 5,
                 10, "the attacker's own command and state")
        wait_for(lambda: any(key == k.alive(rid) for t, key in w.tokens if t > went), 10,
                 "the attacker's own token")
        assert sorted(set(w.puts)) == sorted({k.cmd(rid), k.state(rid)}), w.puts
        assert {key for t, key in w.tokens if t > went} == {k.alive(rid)}, w.tokens
        assert w.queries == [] and report["replies"] == {}, (w.queries, report)
        # what it heard: the control and the team's states only
        assert set(report["heard"]) == {k.sense(rid), k.state(0)}, report["heard"]
        assert report["tokens_seen"] == [k.alive(0)], report["tokens_seen"]
        # what it would answer: nobody is routed to its queryables, nor told of them
        for key in (f"{ns}/robot/{rid}/answer", k.progress()):
            answers = [r.ok.payload.to_bytes() for r in w.speak.get(key, timeout=0.5)
                       if r.ok is not None]
            assert b"attacker answer" not in answers, (key, answers)
        assert w.speak.get(k.progress(), timeout=0.5)  # the control: the watcher's answer
        querier = w.speak.declare_querier(f"{ns}/robot/{rid}/answer")
        control = w.speak.declare_querier(k.progress())  # the watcher's own queryable
        wait_for(lambda: control.matching_status.matching, 10, "the control's queryable")
        assert not querier.matching_status.matching  # its own would have been as quick
        proc.stdin.write("bye\n")
        proc.stdin.flush()
        out, _ = proc.communicate(timeout=30)
        assert json.loads(out.strip().splitlines()[-1]) == {"asked": []}, out
    finally:
        stop(proc)
        w.close()


def test_a_revoked_robot_is_refused_at_once_including_on_its_open_link(tmp_path: Path
                                                                       ) -> None:
    """Issue 19, item 8: a stolen robot key worked until it expired, and a re-issued
    certificate had the same name, so the old one kept working. Revoking robot 1: its
    generation raised to 2 in the fleet file, its certificate issued again under the
    new name (`btrack deploy certs --robot 1`), the router's configuration rendered
    again and the router restarted (Zenoh reads its access control only at start). The
    stolen generation-1 certificate's open link ends with the restart; it reconnects
    (its CA is still the fleet's) but nothing it puts reaches anyone, while the new
    certificate's puts do."""
    import dataclasses

    from deploy.certs import reissue_robot_cert
    from wire import decode

    b = Bus(tmp_path, robots=2)
    try:
        session, _ = open_observer(b)
        with session:
            tls = tmp_path / "tls"
            stolen = b.robot_config(1)
            for suffix in ("pem", "key"):  # the thief's copy of generation 1
                (tls / f"stolen.{suffix}").write_bytes((tls / f"robot-1.{suffix}").read_bytes())
            stolen["transport"]["link"]["tls"].update(
                connect_certificate=str(tls / "stolen.pem"),
                connect_private_key=str(tls / "stolen.key"))
            key = Keys(b.ns).cmd(1)
            heard: list[tuple[float, float]] = []  # (arrival, the command's t: who sent it)
            watch = session.declare_subscriber(key, lambda s: heard.append(
                (time.time(), decode(Cmd, s.payload.to_bytes()).t)))
            thief_t, new_t = 0.0, 1.0

            def count(who: float, since: float) -> int:
                return sum(1 for at, t in list(heard) if t == who and at > since)

            with zenoh.open(zenoh.Config.from_json5(json.dumps(stolen))) as thief:
                deadline = time.monotonic() + 20
                while count(thief_t, 0.0) < 10 and time.monotonic() < deadline:
                    thief.put(key, encode(Cmd(thief_t, 0, 1, 0.0, 0.0)))
                    time.sleep(0.02)
                assert count(thief_t, 0.0) >= 10, "generation 1 worked before the revocation"
                robots = tuple(dataclasses.replace(r, generation=2) if r.id == 1 else r
                               for r in b.fleet.robots)
                fleet = dataclasses.replace(b.fleet, robots=robots)
                reissue_robot_cert(fleet, tls, 1, flat=True)
                conf = router_config(fleet, "127.0.0.1")
                add_test_observer(conf, tls)
                names = [n for subject in conf["access_control"]["subjects"]
                         for n in subject["cert_common_names"]]
                assert Fleet.common_name(1) not in names and Fleet.common_name(1, 2) in names
                stop(b.proc)
                restarted = time.time()
                b.proc = start(["router", "--zenoh-config", str(b.write("router2", conf))],
                               log=tmp_path / "router2.log")
                opened: list[zenoh.Session] = []

                def new_certificate_joins() -> bool:
                    try:
                        opened.append(zenoh.open(zenoh.Config.from_json5(
                            json.dumps(b.robot_config(1)))))
                    except zenoh.ZError:
                        return False
                    return True

                wait_for(new_certificate_joins, 30, "the restarted router")
                with opened[0] as new:
                    deadline = time.monotonic() + 30
                    while count(new_t, restarted) < 10 and time.monotonic() < deadline:
                        new.put(key, encode(Cmd(new_t, 1, 1, 0.0, 0.0)))
                        thief.put(key, encode(Cmd(thief_t, 0, 1, 0.0, 0.0)))  # all along
                        time.sleep(0.02)
                    assert count(new_t, restarted) >= 10, "the new certificate was refused"
                    for _ in range(50):  # and the thief a second more, on its new link
                        thief.put(key, encode(Cmd(thief_t, 0, 1, 0.0, 0.0)))
                        time.sleep(0.02)
            watch.undeclare()
            assert count(thief_t, restarted) == 0, "the revoked certificate still got through"
    finally:
        stop(b.proc)
