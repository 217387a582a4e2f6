"""The rendered systemd units as systemd judges them, and as a host gets them.

- ``systemd-analyze security --offline=true`` scores every unit of the example fleet,
  and of the same fleet with hardware and the localizer, 3.0 or lower (it was 9.0,
  UNSAFE, for each).
- Each host's ``install.sh``, read command by command, installs every file the host's
  units name (environment files, Zenoh configurations and the certificates and keys
  those name) so that the service user can read it and cannot change it, and no key
  so that anyone else can read it. As root, the script is also run for real, into a
  scratch root, and the files are opened as the service user.
"""

from __future__ import annotations

import dataclasses
import grp
import json
import os
import pwd
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import pytest

from deploy.certs import make_fleet_certs
from deploy.fleet import Fleet, parse
from deploy.render import UNIT_DIR, render, write
from tests.unitfiles import host_files, reads

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "deploy" / "examples" / "fleet.toml"
SITES = ROOT / "deploy" / "examples" / "fleet-sites.toml"
BTRACK = str(Path(sys.executable).parent / "btrack")
MAX_EXPOSURE = 3.0


def example() -> Fleet:
    return dataclasses.replace(parse(EXAMPLE.read_text()), btrack=BTRACK)


def hardware() -> Fleet:
    fleet = example()
    return dataclasses.replace(fleet, epoch=1767225600.0, base=dataclasses.replace(
        fleet.base, world="hardware", localizer=True))


def rendered_units(fleets: list[Fleet], out: Path) -> list[Path]:
    """Every unit the fleets render, one file per unit name; a template (``name@``) as
    the instance of robot 1, which is what systemd can judge."""
    units: dict[str, str] = {}
    for fleet in fleets:
        for rel, text in render(fleet).items():
            if f"/{UNIT_DIR}/" in rel:
                units.setdefault(rel.rsplit("/", 1)[1], text)
    write(units, out)
    paths = []
    for name in sorted(units):
        if name.endswith("@.service"):
            instance = out / name.replace("@.service", "@1.service")
            instance.symlink_to(name)
            paths.append(instance)
        else:
            paths.append(out / name)
    return paths


def exposure(unit: Path) -> tuple[float, str]:
    res = subprocess.run(["systemd-analyze", "security", "--offline=true", str(unit)],
                         capture_output=True, text=True, timeout=60)
    text = res.stdout + res.stderr
    found = re.search(r"Overall exposure level for \S+: (\d+\.\d+)", text)
    assert found, text
    return float(found.group(1)), text


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze here")
def test_every_rendered_unit_has_an_exposure_of_3_or_lower(tmp_path: Path) -> None:
    units = rendered_units([example(), hardware()], tmp_path)
    names = {u.name for u in units}
    assert {"btrack-router.service", "btrack-world.service", "btrack-recorder.service",
            "btrack-localizer.service", "btrack-hwbridge.service",
            "btrack-agent@1.service", "btrack-bridge@1.service"} <= names, names
    scores = {}
    for unit in units:
        score, text = exposure(unit)
        scores[unit.name] = score
        failed = [ln for ln in text.splitlines() if ln.startswith("✗")]
        assert score <= MAX_EXPOSURE, (unit.name, score, "\n".join(failed))
    print(scores)


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="no systemd-analyze here")
def test_a_router_on_a_port_below_1024_may_bind_it_and_nothing_more(tmp_path: Path) -> None:
    fleet = example()
    low = dataclasses.replace(fleet, base=dataclasses.replace(fleet.base, port=443))
    text = render(low)[f"base.lab/{UNIT_DIR}/btrack-router.service"]
    assert "CapabilityBoundingSet=CAP_NET_BIND_SERVICE\n" in text
    assert "AmbientCapabilities=CAP_NET_BIND_SERVICE\n" in text
    assert "PrivateUsers=yes" not in text  # its capability must count on the host
    others = [v for k, v in render(low).items() if k.endswith(".service")
              and not k.endswith("btrack-router.service")]
    assert others and all("CapabilityBoundingSet=\n" in v for v in others)
    (tmp_path / "btrack-router.service").write_text(text)
    score, report = exposure(tmp_path / "btrack-router.service")
    assert score <= MAX_EXPOSURE, report


# --- install.sh -----------------------------------------------------------------------


@dataclass(frozen=True)
class Installed:
    """One path as the install script leaves it."""

    mode: int
    owner: str
    group: str
    source: str | None  # None: a directory

    def allows(self, user: str, group: str, bit: int) -> bool:
        """Whether ``user`` (primary group ``group``) has permission ``bit`` (4 read,
        2 write, 1 search) on it."""
        if self.owner == user:
            return bool(self.mode >> 6 & bit)
        if self.group == group:
            return bool(self.mode >> 3 & bit)
        return bool(self.mode & bit)


SYSTEM_DIR = Installed(0o755, "root", "root", None)  # /, /etc, ... as a system has them


def read_install(script: str, user: str, group: str) -> dict[str, Installed]:
    """What ``install.sh`` does, from its commands: path on the host -> how it is left.
    A command this reader does not know fails the test, so the script cannot do more
    than is checked here."""
    done: dict[str, Installed] = {}
    made_user = False
    for line in script.splitlines():
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        if line in ("#!/bin/sh", "set -eu", 'cd "$(dirname "$0")"', 'ROOT="${ROOT:-}"',
                    'G="$(id -gn "$U")"'):
            continue
        if line.startswith("U="):
            assert line == f"U={user}", line
            continue
        if line.startswith('getent passwd "$U" >/dev/null || useradd '):
            assert "--system" in line and '"$U"' in line, line
            made_user = True
            continue
        words = [w.replace("$ROOT", "").replace("$G", group).replace("$U", user)
                 for w in shlex.split(line)]
        assert words[0] == "install", f"install.sh: unknown command {line!r}"
        opts: dict[str, str] = {}
        args, directory, i = [], False, 1
        while i < len(words):
            if words[i] == "-d":
                directory = True
            elif words[i] in ("-m", "-o", "-g"):
                opts[words[i]] = words[i + 1]
                i += 1
            else:
                args.append(words[i])
            i += 1
        mode, owner, grp_ = int(opts["-m"], 8), opts["-o"], opts["-g"]
        if directory:
            for d in args:
                done[d] = Installed(mode, owner, grp_, None)
        else:
            src, dest = args
            assert dest not in done, f"{dest} installed twice"
            done[dest] = Installed(mode, owner, grp_, src)
    assert made_user, "install.sh does not make the service user"
    return done


def unit_needs(files: dict[str, str], fleet: Fleet, host: str) -> dict[str, set[str]]:
    """For every unit of ``host`` (a template once per robot id of the host), the files
    its process must read (``unitfiles.reads``)."""
    needs: dict[str, set[str]] = {}
    for path in host_files(files, host):
        if not path.startswith(f"/{UNIT_DIR}/"):
            continue
        name = PurePosixPath(path).name
        ids = [str(r.id) for r in fleet.robots if r.host == host] if "@." in name else [""]
        for i in ids:
            needs[name.replace("@.", f"@{i}.")] = reads(files, host, name, i)
    return needs


def check_install(files: dict[str, str], fleet: Fleet, tree: Path | None) -> None:
    user, group = fleet.user, fleet.user  # useradd --user-group: a group of its name
    hosts = fleet.hosts
    for host in hosts:
        done = read_install(files[f"{host}/install.sh"], user, group)
        # every file of the host, rendered or certificate, goes where it belongs
        rendered = {k.split("/", 1)[1] for k in files if k.startswith(host + "/")}
        rendered.discard("install.sh")
        tls = {f"{fleet.tls.dir.strip('/')}/{n}": secret
               for n, secret in fleet.tls_files(host).items()}
        sources = {e.source for e in done.values() if e.source}
        assert sources == rendered | set(tls), (host, sources ^ (rendered | set(tls)))
        for dest, e in done.items():
            if e.source:
                assert dest == "/" + e.source, (dest, e)
                assert tree is None or (tree / host / e.source).is_file(), e.source
            if dest.startswith(f"/{UNIT_DIR}/"):  # systemd's to read, root's to change
                assert (e.mode, e.owner, e.group) == (0o644, "root", "root"), (dest, e)
        needs = unit_needs(files, fleet, host)
        assert needs, host
        for unit, needed in needs.items():
            for path in needed:
                assert path in done, (host, unit, path, "not installed")
                e = done[path]
                assert e.allows(user, group, 4), (unit, path, e, "unreadable by the service")
                assert not e.allows(user, group, 2), (unit, path, e, "the service may change it")
                for parent in PurePosixPath(path).parents:
                    d = done.get(str(parent), SYSTEM_DIR)
                    assert d.source is None and d.allows(user, group, 1), (unit, parent, d)
                    assert not d.allows(user, group, 2), (unit, parent, d, "writable")
        for rel, secret in tls.items():
            if secret:
                e = done["/" + rel]
                assert e.mode & 0o007 == 0 and e.owner == "root", (rel, e)


@pytest.fixture(scope="module")
def rendered_with_certs(tmp_path_factory) -> tuple[Fleet, dict[str, str], Path]:
    if shutil.which("openssl") is None:
        pytest.skip("no openssl command")
    out = tmp_path_factory.mktemp("tree")
    fleet = hardware()
    files = render(fleet)
    write(files, out)
    make_fleet_certs(fleet, out)
    return fleet, files, out


def test_install_sh_leaves_every_file_a_unit_reads_readable_by_its_user_only(
        rendered_with_certs) -> None:
    fleet, files, tree = rendered_with_certs
    check_install(files, fleet, tree)
    check_install(render(example()), example(), None)


def test_install_sh_of_a_fleet_over_sites_installs_each_routers_files(tmp_path: Path) -> None:
    """Three routers meshed (``[[routers]]``): each router host installs its router's
    configuration, unit and certificate, the base station its router-0 certificate."""
    if shutil.which("openssl") is None:
        pytest.skip("no openssl command")
    fleet = dataclasses.replace(parse(SITES.read_text()), btrack=BTRACK)
    files = render(fleet)
    write(files, tmp_path)
    make_fleet_certs(fleet, tmp_path)
    check_install(files, fleet, tmp_path)
    for k, host in enumerate(fleet.router_hosts):
        done = read_install(files[f"{host}/install.sh"], fleet.user, fleet.user)
        assert f"{fleet.tls.dir}/router-{k}.key" in done, host
        assert f"{fleet.config_dir}/zenoh-router.json5" in done, host


def test_install_sh_makes_a_recordings_directory_outside_var_lib() -> None:
    fleet = example()
    srv = dataclasses.replace(fleet, base=dataclasses.replace(fleet.base,
                                                              recorder_dir="/srv/btrack"))
    files = render(srv)
    unit = files[f"base.lab/{UNIT_DIR}/btrack-recorder.service"]
    assert "ReadWritePaths=/srv/btrack\n" in unit and "StateDirectory" not in unit
    done = read_install(files["base.lab/install.sh"], "btrack", "btrack")
    assert done["/srv/btrack"] == Installed(0o750, "btrack", "btrack", None)
    assert "StateDirectory=btrack/runs\n" in render(fleet)[
        f"base.lab/{UNIT_DIR}/btrack-recorder.service"]


@pytest.mark.skipif(os.geteuid() != 0, reason="installs as root, reads as the service user")
def test_install_sh_run_for_real_then_read_as_the_service_user(rendered_with_certs) -> None:
    """The scripts run (into a scratch root, for the existing user ``nobody``); then a
    process with nobody's credentials opens every file its units need, and may not
    write one; a process of another user may not read a key."""
    fleet0, _, tree0 = rendered_with_certs
    fleet = dataclasses.replace(fleet0, user="nobody")
    files = render(fleet)
    work = Path(tempfile.mkdtemp(prefix="btrack-install-", dir="/tmp"))
    try:
        os.chmod(work, 0o755)  # so that nobody may reach the scratch roots
        write(files, work / "tree")
        for host in fleet.hosts:
            shutil.copytree(tree0 / host / fleet.tls.dir.strip("/"),
                            work / "tree" / host / fleet.tls.dir.strip("/"))
            root = work / "root" / host
            res = subprocess.run(["sh", str(work / "tree" / host / "install.sh")],
                                 env={**os.environ, "ROOT": str(root)},
                                 capture_output=True, text=True, timeout=60)
            assert res.returncode == 0, res.stderr
            needs = sorted({str(root) + p for ps in unit_needs(files, fleet, host).values()
                            for p in ps})
            keys = [str(root) + "/" + fleet.tls.dir.strip("/") + "/" + n
                    for n, secret in fleet.tls_files(host).items() if secret]
            assert as_user("nobody", needs, needs[:1]) == {"read": len(needs), "wrote": 0}
            # a user of no group of ours (the uid of no one)
            assert as_user(4242, keys, []) == {"read": 0, "wrote": 0}
    finally:
        shutil.rmtree(work)


def as_user(who: str | int, reads: list[str], writes: list[str]) -> dict[str, int]:
    """How many of ``reads`` a process of ``who`` can read, and of ``writes`` append to."""
    if isinstance(who, str):
        pw = pwd.getpwnam(who)
        ids = ["--reuid", str(pw.pw_uid), "--regid", str(pw.pw_gid), "--init-groups"]
        assert grp.getgrgid(pw.pw_gid)
    else:
        ids = ["--reuid", str(who), "--regid", str(who), "--clear-groups"]
    probe = """
import json, sys
paths = json.loads(sys.argv[1])
n = {"read": 0, "wrote": 0}
for p in paths["reads"]:
    try:
        open(p, "rb").read(); n["read"] += 1
    except PermissionError:
        pass
for p in paths["writes"]:
    try:
        open(p, "ab").close(); n["wrote"] += 1
    except PermissionError:
        pass
print(json.dumps(n))
"""
    res = subprocess.run(["setpriv", *ids, sys.executable, "-I", "-c", probe,
                          json.dumps({"reads": reads, "writes": writes})],
                         capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)
