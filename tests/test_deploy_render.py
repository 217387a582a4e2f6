"""`btrack deploy render` on the example fleet file: every host gets its files, the
units pass `systemd-analyze verify`, the JSON5 files load in zenoh, the access control
is what a robot needs and no more; bad fleet files are refused by key and line."""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import zenoh

from deploy.fleet import FleetError, parse
from deploy.render import render, write

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "deploy" / "examples" / "fleet.toml"
BTRACK = Path(sys.executable).parent / "btrack"
HOSTS = {"base.lab", "robot0.lab", "robot1.lab", "robot2.lab"}


def btrack(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "btrack", *args], capture_output=True,
                          text=True, timeout=60)


def render_tree(fleet_file: Path, out: Path) -> Path:
    """``btrack deploy render`` of a fleet file into ``out``."""
    # The units name the btrack command; point it at this venv's so verify finds it.
    res = btrack("deploy", "render", str(fleet_file), "--out", str(out), "--btrack", str(BTRACK))
    assert res.returncode == 0, res.stderr
    return out


@pytest.fixture(scope="module")
def rendered(tmp_path_factory) -> Path:
    return render_tree(EXAMPLE, tmp_path_factory.mktemp("render"))


def test_every_host_gets_its_files(rendered: Path) -> None:
    assert {p.name for p in rendered.iterdir() if p.is_dir()} == HOSTS
    base = rendered / "base.lab"
    for rel in ("etc/btrack/zenoh-router.json5", "etc/btrack/zenoh-world.json5",
                "etc/btrack/zenoh-recorder.json5", "etc/btrack/base.env",
                "etc/systemd/system/btrack-router.service",
                "etc/systemd/system/btrack-world.service",
                "etc/systemd/system/btrack-recorder.service"):
        assert (base / rel).is_file(), rel
    for i in range(3):
        host = rendered / f"robot{i}.lab"
        assert (host / f"etc/btrack/zenoh-agent-{i}.json5").is_file()
        env = (host / f"etc/btrack/agent-{i}.env").read_text()
        assert f"ZENOH_CONFIG=/etc/btrack/zenoh-agent-{i}.json5" in env
        assert "BTRACK_ROBOTS=3" in env and "BTRACK_NS=btrack/lab1" in env
        unit = (host / "etc/systemd/system/btrack-agent@.service").read_text()
        assert f"ExecStart={BTRACK} agent --id %i" in unit
        assert "EnvironmentFile=/etc/btrack/agent-%i.env" in unit
        assert "Restart=on-failure" in unit
        # a robot computer holds no one else's files
        assert not list(host.rglob("zenoh-router.json5"))
        assert [p.name for p in host.rglob("*.json5")] == [f"zenoh-agent-{i}.json5"]
    assert "btrack-agent@1" in (rendered / "INSTALL.md").read_text()


def test_json5_files_load_in_zenoh(rendered: Path) -> None:
    files = sorted(rendered.rglob("*.json5"))
    assert len(files) == 6  # the router, the world, the recorder, three robots
    for path in files:
        conf = zenoh.Config.from_file(str(path))
        text = str(conf)
        assert '"lease":1000' in text.replace(" ", ""), path
        assert '"tls":{' in text.replace(" ", ""), path
    router = str(zenoh.Config.from_file(str(rendered / "base.lab/etc/btrack/zenoh-router.json5")))
    assert '"enable_mtls":true' in router.replace(" ", "")
    assert '"default_permission":"deny"' in router.replace(" ", "")
    robot = str(zenoh.Config.from_file(str(rendered / "robot2.lab/etc/btrack/zenoh-agent-2.json5")))
    assert "tls/base.lab:7447" in robot and "/etc/btrack/tls/robot-2.pem" in robot
    for role in ("world", "recorder"):  # each base station process with its own certificate
        path = rendered / f"base.lab/etc/btrack/zenoh-{role}.json5"
        conf = str(zenoh.Config.from_file(str(path)))
        assert "tls/localhost:7447" in conf and f"/etc/btrack/tls/{role}.pem" in conf
        unit = (rendered / f"base.lab/etc/systemd/system/btrack-{role}.service").read_text()
        assert f"--zenoh-config /etc/btrack/zenoh-{role}.json5" in unit


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze here")
def test_units_pass_systemd_analyze_verify(rendered: Path, tmp_path: Path) -> None:
    units = sorted((rendered / "base.lab/etc/systemd/system").glob("*.service"))
    # and the units the example leaves out: hardware bridges and the localizer
    fleet = parse(EXAMPLE.read_text())
    hw = dataclasses.replace(fleet, btrack=str(BTRACK), epoch=1767225600.0,
                             base=dataclasses.replace(fleet.base, world="hardware",
                                                      localizer=True))
    hw_units = {k: v for k, v in render(hw).items() if k.endswith((
        "btrack-hwbridge.service", "btrack-localizer.service"))}
    assert len(hw_units) == 2 and "btrack-world.service" not in " ".join(render(hw))
    write(hw_units, tmp_path / "hw")
    units += sorted((tmp_path / "hw").rglob("*.service"))
    # A template is verified through an instance: robot 1's, beside the template.
    agent_dir = tmp_path / "agent"
    agent_dir.mkdir()
    shutil.copy(rendered / "robot1.lab/etc/systemd/system/btrack-agent@.service", agent_dir)
    (agent_dir / "btrack-agent@1.service").symlink_to("btrack-agent@.service")
    bridge = render(hw)["robot1.lab/etc/systemd/system/btrack-bridge@.service"]
    (agent_dir / "btrack-bridge@.service").write_text(bridge)
    (agent_dir / "btrack-bridge@1.service").symlink_to("btrack-bridge@.service")
    for group in (units, [agent_dir / "btrack-agent@1.service",
                          agent_dir / "btrack-bridge@1.service"]):
        res = subprocess.run(["systemd-analyze", "verify", *map(str, group)],
                             capture_output=True, text=True, timeout=60)
        # verify returns 0 on unknown keys; they only show as warnings, so none is allowed
        assert res.returncode == 0 and not (res.stdout + res.stderr).strip(), (
            res.stdout + res.stderr)


def test_robot_may_publish_only_its_own_keys_in_the_rendered_acl() -> None:
    fleet = parse(EXAMPLE.read_text())
    acl = render_router_acl(fleet)
    rules = {r["id"]: r for r in acl["rules"]}
    put = rules["robot1-put"]
    assert put["flows"] == ["ingress"] and put["messages"] == ["put"]
    assert put["key_exprs"] == ["btrack/lab1/robot/1/cmd", "btrack/lab1/agent/1/state"]
    assert rules["robot1-token"]["key_exprs"] == ["btrack/lab1/alive/agent/1"]
    subjects = {s["id"]: s for s in acl["subjects"]}
    assert subjects["robot1"]["cert_common_names"] == ["btrack-robot-1"]
    # every base station process has a name of its own; the router's has no rights
    assert {s["id"]: s["cert_common_names"] for s in acl["subjects"]
            if not s["id"].startswith("robot")} == {
        "world": ["btrack-world"], "recorder": ["btrack-recorder"]}
    assert not [s for s in acl["subjects"] if "btrack-base" in s["cert_common_names"]]
    # no robot rule lets it put or declare a token on a key with a wildcard
    for rule in acl["rules"]:
        if rule["id"].startswith("robot") and "ingress" in rule["flows"]:
            if {"put", "liveliness_token", "delete"} & set(rule["messages"]):
                assert all("*" not in k for k in rule["key_exprs"]), rule


def render_router_acl(fleet):
    from deploy.render import access_control

    return access_control(fleet)


def test_render_is_deterministic() -> None:
    fleet = parse(EXAMPLE.read_text())
    assert render(fleet) == render(fleet)


def make_certs(fleet_file: Path, out: Path) -> None:
    """``btrack deploy certs`` of a fleet file into ``out`` (skipped without openssl)."""
    if shutil.which("openssl") is None:
        pytest.skip("no openssl command")
    res = btrack("deploy", "certs", str(fleet_file), "--out", str(out))
    assert res.returncode == 0, res.stderr


def subject(pem: Path) -> str:
    """A certificate's subject and alternative names, as openssl prints them."""
    return subprocess.run(["openssl", "x509", "-noout", "-subject", "-ext", "subjectAltName",
                           "-in", str(pem)], capture_output=True, text=True).stdout


def chains(tls: Path, pem: str) -> None:
    """The certificate ``pem`` of a host's TLS dir chains to the ``ca.pem`` beside it."""
    ok = subprocess.run(["openssl", "verify", "-CAfile", str(tls / "ca.pem"), str(tls / pem)],
                        capture_output=True, text=True)
    assert ok.returncode == 0, ok.stderr


def test_certs_for_the_fleet_chain_to_its_ca(tmp_path: Path) -> None:
    make_certs(EXAMPLE, tmp_path)
    tls = tmp_path / "robot1.lab/etc/btrack/tls"
    assert sorted(p.name for p in tls.iterdir()) == ["ca.pem", "robot-1.key", "robot-1.pem"]
    base = tmp_path / "base.lab/etc/btrack/tls"
    assert sorted(p.name for p in base.iterdir()) == [
        "base.key", "base.pem", "ca.pem", "recorder.key", "recorder.pem", "world.key",
        "world.pem"]
    assert "CN = btrack-world" in subject(base / "world.pem")
    assert (tls / "robot-1.key").stat().st_mode & 0o077 == 0
    assert not list(tmp_path.glob("*.lab/**/ca.key"))  # the CA key stays off the hosts
    chains(tls, "robot-1.pem")
    subj = subject(base / "base.pem")
    assert "CN = btrack-base" in subj and "base.lab" in subj and "192.168.50.1" in subj
    # revoking robot 1: its generation raised, its certificate alone issued again by the CA
    fleet = tmp_path / "fleet.toml"
    fleet.write_text(EXAMPLE.read_text().replace('id = 1\n', 'id = 1\ngeneration = 2\n', 1))
    before = (base / "world.pem").read_bytes()
    res = btrack("deploy", "certs", str(fleet), "--out", str(tmp_path), "--robot", "1")
    assert res.returncode == 0 and "generation 2" in res.stdout, res.stderr
    assert "CN = btrack-robot-1-g2" in subject(tls / "robot-1.pem")
    chains(tls, "robot-1.pem")
    assert (base / "world.pem").read_bytes() == before


# the last five: a fleet over sites ([[routers]]) with a bad router index, host or key
SITES_HEAD = ('namespace = "a"\n[base]\nhost = "b"\n[[routers]]\nhost = "n"\n'
              '[[routers]]\nhost = "s"\n')
BAD = [
    ('namespace = "a"\n[base]\nhost = "b"\nbogus = 1\n[[robots]]\nid = 0\nhost = "r"\n',
     ":4: base.bogus: unknown key"),
    ('namespace = "a"\n[base]\nhost = "b"\n[[robots]]\nid = 0\nhost = "r"\n'
     '[[robots]]\nid = 0\nhost = "s"\n', ":8: robots[1].id: duplicate robot id 0"),
    ('namespace = "a"\n[base]\nport = 7447\n[[robots]]\nid = 0\nhost = "r"\n',
     "base.host: missing"),
    ('namespace = "a"\n[base]\nhost = "b"\nport = 99999\n[[robots]]\nid = 0\nhost = "r"\n',
     ":4: base.port: must be in 1..65535"),
    ('namespace = "a"\n[base]\nhost = "b"\n[[robots]]\nid = 1\nhost = "r"\n',
     "robot ids must be 0..0"),
    ('namespace = "a"\n[base]\nhost = "b"\n[[robots]]\nid = 0\nhost = "r"\n'
     '[tls]\nenabled = false\n', "tls.access_control: needs enabled = true"),
    ('namespace = "a"\n[base\nhost = "b"\n', "not valid TOML"),
    ('namespace = "a b"\n[base]\nhost = "b"\n[[robots]]\nid = 0\nhost = "r"\n',
     ":1: namespace:"),
    ('namespace = "a"\n[base]\nhost = "b"\nworld = "hardware"\n[[robots]]\nid = 0\n'
     'host = "r"\n', ':4: base.world: world = "hardware" needs a top-level epoch'),
    ('namespace = "a"\nepoch = 1\n[base]\nhost = "b"\nworld = "hardware"\nlocalizer = false\n'
     '[[robots]]\nid = 0\nhost = "r"\n', ':6: base.localizer: world = "hardware" needs the'),
    ('namespace = "a"\n[base]\nhost = "b"\n[[robots]]\nid = 0\nhost = "r"\nport = "ttyUSB0"\n',
     ":7: robots[0].port: must be an absolute path"),
    ('namespace = "a"\n[base]\nhost = "b"\n[[robots]]\nid = 0\nhost = "r"\ngeneration = 0\n',
     ":7: robots[0].generation: must be >= 1"),
    (SITES_HEAD + '[[robots]]\nid = 0\nhost = "r"\nrouter = 3\n',
     ":11: robots[0].router: must be 0 (the base station's) .. 2 (the [[routers]] in "
     "order), got 3"),
    (SITES_HEAD + '[[routers]]\nhost = "n"\n[[robots]]\nid = 0\nhost = "r"\n',
     ":9: routers[2].host: n has a router already"),
    ('namespace = "a"\n[base]\nhost = "b"\n[[routers]]\nhost = "b"\n'
     '[[robots]]\nid = 0\nhost = "r"\n', ":5: routers[0].host: b has a router already"),
    ('namespace = "a"\n[base]\nhost = "b"\n[[routers]]\nhost = "n"\nport = 1\n'
     '[[robots]]\nid = 0\nhost = "r"\n', ":6: routers[0].port: unknown key"),
    ('namespace = "a"\nrouters = 3\n[base]\nhost = "b"\n[[robots]]\nid = 0\nhost = "r"\n',
     "routers: expected [[routers]] tables"),
]


@pytest.mark.parametrize("text,expected", BAD)
def test_bad_fleet_is_refused_by_key_and_line(text: str, expected: str) -> None:
    with pytest.raises(FleetError) as err:
        parse(text, "f.toml")
    assert expected in str(err.value), str(err.value)


def test_cli_refuses_a_bad_fleet_without_a_traceback(tmp_path: Path) -> None:
    bad = tmp_path / "fleet.toml"
    bad.write_text(BAD[0][0])
    res = btrack("deploy", "render", str(bad), "--out", str(tmp_path / "out"))
    assert res.returncode == 2
    assert "fleet.toml:4: base.bogus: unknown key" in res.stderr
    assert "Traceback" not in res.stderr
    assert not (tmp_path / "out").exists()
    missing = btrack("deploy", "render", str(tmp_path / "nope.toml"), "--out", str(tmp_path))
    assert missing.returncode == 2 and "cannot read" in missing.stderr
    latin = tmp_path / "latin1.toml"  # issue 19, item 6: was a UnicodeDecodeError traceback
    latin.write_bytes('namespace = "a"\n# caf\u00e9\n'.encode("latin-1"))
    res = btrack("deploy", "render", str(latin), "--out", str(tmp_path / "out"))
    assert res.returncode == 2 and "Traceback" not in res.stderr
    assert "latin1.toml:2: not UTF-8 text (byte 21" in res.stderr
    for args in (["deploy", "--help"], ["deploy", "render", "--help"], ["router", "--help"]):
        assert btrack(*args).returncode == 0


def test_a_hardware_fleets_localizer_takes_the_scans_at_their_measured_times() -> None:
    """A real LMS sends scans at its own rate (5 a second at 38400 baud), each stamped
    with its measurement time by the bridge: the localizer must not wait for one scan
    per tick, as in simulation."""
    fleet = parse(EXAMPLE.read_text())
    hw = dataclasses.replace(fleet, epoch=1767225600.0,
                             base=dataclasses.replace(fleet.base, world="hardware",
                                                      localizer=True))
    for f, measured in ((fleet, False), (hw, True)):
        env = next(v for k, v in render(f).items() if k.endswith("/base.env"))
        line = next(x for x in env.splitlines() if x.startswith("BTRACK_LOCALIZER_ARGS="))
        assert ("--timing measured" in line) is measured, line


def test_a_mesh_router_connects_to_the_others_and_lets_only_them_route() -> None:
    from deploy.render import client_config, mesh_router_config

    fleet = parse(EXAMPLE.read_text())
    addrs = ["10.0.0.1", "10.0.0.2", "10.0.0.3"]
    conf = mesh_router_config(fleet, 1, addrs)
    assert conf["connect"]["endpoints"] == ["tls/10.0.0.1:7447", "tls/10.0.0.3:7447"]
    tls = conf["transport"]["link"]["tls"]
    assert tls["connect_certificate"].endswith("/router-1.pem")
    assert tls["listen_certificate"] == tls["connect_certificate"]
    acl = conf["access_control"]
    assert acl["default_permission"] == "deny"
    subjects = {s["id"]: s["cert_common_names"] for s in acl["subjects"]}
    assert subjects["mesh"] == ["btrack-router-0", "btrack-router-1", "btrack-router-2"]
    # every client keeps exactly its own rights beside the mesh's
    assert {k: v for k, v in subjects.items() if k != "mesh"} == {
        s["id"]: s["cert_common_names"] for s in render_router_acl(fleet)["subjects"]}
    mesh = [r for r in acl["rules"] if r["id"].startswith("mesh-")]
    assert {f for r in mesh for f in r["flows"]} == {"ingress", "egress"}
    assert all(r["key_exprs"] == ["btrack/lab1/**"] for r in mesh)
    zenoh.Config.from_json5(json.dumps(conf))  # Zenoh takes it
    with pytest.raises(ValueError, match="router 3"):
        mesh_router_config(fleet, 3, addrs)
    # a robot's client lists its own router first, then the others in turn, once each
    robot = client_config(fleet, fleet.robot(2), host="10.0.0.3",
                          fallbacks=("10.0.0.1", "10.0.0.3", "10.0.0.2"))
    assert robot["connect"]["endpoints"] == [
        "tls/10.0.0.3:7447", "tls/10.0.0.1:7447", "tls/10.0.0.2:7447"]


# a fleet over three sites: [[routers]] meshed with the base station's ---------------
SITES = ROOT / "deploy" / "examples" / "fleet-sites.toml"
SITE_ROUTERS = ("base.coast", "north.coast", "south.coast")


@pytest.fixture(scope="module")
def sites(tmp_path_factory) -> Path:
    return render_tree(SITES, tmp_path_factory.mktemp("sites"))


def test_a_fleet_over_sites_gives_every_router_host_a_meshed_router(sites: Path) -> None:
    fleet = parse(SITES.read_text())
    assert fleet.router_hosts == SITE_ROUTERS
    assert {p.name for p in sites.iterdir() if p.is_dir()} == set(fleet.hosts)
    for k, host in enumerate(SITE_ROUTERS):
        path = sites / host / "etc/btrack/zenoh-router.json5"
        conf = zenoh.Config.from_file(str(path))  # Zenoh takes it
        text = str(conf).replace(" ", "")
        assert f"/etc/btrack/tls/router-{k}.pem" in text, host
        others = [h for h in SITE_ROUTERS if h != host]
        for other in others:  # connects to every other router, by name
            assert f"tls/{other}:7447" in text, (host, other)
        assert f"tls/{host}:7447" not in text  # and not to itself
        assert json.loads(conf.get_json("transport/unicast/open_timeout")) < 10_000
        assert '"default_permission":"deny"' in text
        assert "btrack-router-0" in text and "btrack-router-2" in text
        # the other sites run only the router there; the base station its own services too
        units = {p.name for p in (sites / host / "etc/systemd/system").iterdir()}
        assert "btrack-router.service" in units
        assert ("btrack-world.service" in units) is (k == 0)
    install = (sites / "INSTALL.md").read_text()
    assert "north.coast" in install and "router-1" in install


def test_a_robot_connects_to_its_sites_router_first_then_round_the_mesh(sites: Path) -> None:
    order = {0: SITE_ROUTERS, 1: SITE_ROUTERS[1:] + SITE_ROUTERS[:1],
             3: SITE_ROUTERS[2:] + SITE_ROUTERS[:2]}
    for rid, hosts in order.items():
        path = sites / f"robot{rid}.coast/etc/btrack/zenoh-agent-{rid}.json5"
        conf = zenoh.Config.from_file(str(path))
        connect = json.loads(conf.get_json("connect"))
        assert connect["endpoints"] == [f"tls/{h}:7447" for h in hosts], rid
        # a hung router (host up, process silent) is left for the next within two
        # leases, not Zenoh's default 10 s of handshake
        lease_ms = json.loads(conf.get_json("transport/link/tx/lease"))
        timeout = json.loads(conf.get_json("transport/unicast/open_timeout"))
        assert timeout == max(1000, 2 * lease_ms) < 10_000, rid
        # its agent holds a neighbour whose token goes while its states come (a router
        # that died took its clients' tokens with it): see deploy.render.agent_args
        env = (sites / f"robot{rid}.coast/etc/btrack/agent-{rid}.env").read_text()
        assert "--token-grace 0.5" in env, env
    # the single-router example is unchanged: one router, no mesh certificates, and
    # Zenoh's own open timeout (there is no other router to go to)
    fleet = parse(EXAMPLE.read_text())
    assert not fleet.meshed and fleet.routers_of(fleet.robot(2)) == ("base.lab",)
    from deploy.render import client_config
    single = client_config(fleet, fleet.robot(2))
    assert "unicast" not in single["transport"]
    from deploy.render import agent_args
    assert "--token-grace" not in agent_args(fleet, fleet.robot(2))


def test_certs_for_a_fleet_over_sites_name_each_router(tmp_path: Path) -> None:
    make_certs(SITES, tmp_path)
    base = tmp_path / "base.coast/etc/btrack/tls"
    names = sorted(p.name for p in base.iterdir())
    assert "router-0.pem" in names and "base.pem" not in names and "world.pem" in names
    for k, host in enumerate(SITE_ROUTERS):
        tls = tmp_path / host / "etc/btrack/tls"
        assert {f"router-{k}.pem", f"router-{k}.key", "ca.pem"} <= {p.name for p in tls.iterdir()}
        subj = subject(tls / f"router-{k}.pem")
        assert f"CN = btrack-router-{k}" in subj and host in subj, subj
        chains(tls, f"router-{k}.pem")
    north = {p.name for p in (tmp_path / "north.coast/etc/btrack/tls").iterdir()}
    assert north == {"ca.pem", "router-1.key", "router-1.pem"}
