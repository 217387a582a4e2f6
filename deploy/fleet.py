"""The fleet file: one TOML file that describes a lab's deployment.

It names the base station (the Zenoh router, the world or the hardware bridges,
the localizer, the recorder), every robot computer (one agent each), the run
namespace, the port, the lease and the certificates; and, for a fleet over more than
one site, the other routers (``[[routers]]``), meshed with the base station's, each
robot a client of one of them (``router = K``) that falls back to the others. ``load``
turns it into frozen dataclasses; anything wrong is refused with a ``FleetError`` that
names the key and, where it can be found, the line at fault.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

_HOST_RE = re.compile(r"^[A-Za-z0-9]([A-Za-z0-9\-.]*[A-Za-z0-9])?$")
_NS_RE = re.compile(r"^[A-Za-z0-9_\-]+(/[A-Za-z0-9_\-]+)*$")
_FILE_RE = re.compile(r"^[A-Za-z0-9_.\-]+$")


class FleetError(ValueError):
    """A fleet file that cannot be deployed; the message names the key (and line)."""


@dataclass(frozen=True)
class Base:
    """The base station: Zenoh router and the shared processes."""

    host: str  # the name robots connect to; it is in the base station's certificate
    address: str | None = None  # an IP robots may use instead; also in the certificate
    port: int = 7447
    # "sim": btrack world here; "hardware": the laser's bridge (btrack bridge lms) here
    # and each robot's Create bridge on its computer; "none"
    world: str = "sim"
    world_args: tuple[str, ...] = ()  # btrack world's, or btrack bridge lms's (hardware)
    laser_port: str = "/dev/ttyUSB1"  # hardware: the SICK LMS's serial device
    localizer: bool = False
    localizer_args: tuple[str, ...] = ()
    recorder: bool = True
    recorder_dir: str = "/var/lib/btrack/runs"
    lease_s: float = 1.0


@dataclass(frozen=True)
class Router:
    """A router of another site, meshed with the base station's (router 0): robots of
    that site connect to it, and to the other routers when it is down."""

    host: str  # the name robots and the other routers connect to; in its certificate
    address: str | None = None  # also in its certificate


def router_common_name(index: int) -> str:
    """The certificate common name of router ``index`` of a mesh (the base station's
    is 0); a single base station's router is ``Fleet.common_name(None)``."""
    return f"btrack-router-{index}"


def router_files(index: int) -> tuple[str, str]:
    """Certificate and key file of router ``index`` of a mesh, in the fleet's TLS dir."""
    return f"router-{index}.pem", f"router-{index}.key"


@dataclass(frozen=True)
class Robot:
    """One robot computer: it runs ``btrack agent --id ID``."""

    id: int
    host: str
    cert: str  # file names under the TLS directory on that host
    key: str
    agent_args: tuple[str, ...] = ()
    port: str = "/dev/ttyUSB0"  # hardware: its Create's serial device
    bridge_args: tuple[str, ...] = ()  # hardware: more for its btrack bridge create
    # Which issue of its certificate the router accepts: raised to revoke the last one
    # (a stolen key), it names the next certificate apart from every earlier one.
    generation: int = 1
    router: int = 0  # the router it connects to first: 0 the base station's, K [[routers]]'s


@dataclass(frozen=True)
class Tls:
    enabled: bool = True
    dir: str = "/etc/btrack/tls"  # where certificates live on every host
    ca: str = "ca.pem"
    base_cert: str = "base.pem"  # the router's (it listens with it)
    base_key: str = "base.key"
    access_control: bool = True  # a robot may publish only its own keys

    @staticmethod
    def role_files(role: str) -> tuple[str, str]:
        """Certificate and key file of a base station process (``Fleet.base_roles``)."""
        return f"{role}.pem", f"{role}.key"


@dataclass(frozen=True)
class Fleet:
    namespace: str
    base: Base
    robots: tuple[Robot, ...]
    tls: Tls = field(default_factory=Tls)
    btrack: str = "/opt/btrack/.venv/bin/btrack"  # the btrack command on every host
    config_dir: str = "/etc/btrack"
    user: str = "btrack"
    lease_s: float = 1.0  # transport lease every robot announces
    agent_args: tuple[str, ...] = ()  # extra arguments for every agent
    # hardware: the run's epoch (Unix seconds) every bridge counts time and ticks from,
    # so that robots of the team share k (their clocks NTP-synchronised)
    epoch: float | None = None
    bridge_args: tuple[str, ...] = ()  # hardware: more for every btrack bridge create
    routers: tuple[Router, ...] = ()  # the other sites' routers, meshed with the base's

    @property
    def team(self) -> int:
        return len(self.robots)

    @property
    def meshed(self) -> bool:
        """Whether the fleet has more than one router (``[[routers]]``)."""
        return bool(self.routers)

    @property
    def router_hosts(self) -> tuple[str, ...]:
        """Every router's host, the base station's first (router 0)."""
        return (self.base.host, *(r.host for r in self.routers))

    @property
    def hosts(self) -> list[str]:
        """Every host of the fleet, once each, sorted."""
        return sorted({*self.router_hosts, *(r.host for r in self.robots)})

    def routers_of(self, robot: Robot) -> tuple[str, ...]:
        """The routers' hosts a robot connects to, in the order it tries them: its own,
        then the next ones round the mesh (so the robots of a router that is down spread
        by site, not all onto the base station)."""
        hosts = self.router_hosts
        return tuple(hosts[(robot.router + j) % len(hosts)] for j in range(len(hosts)))

    def robot(self, rid: int) -> Robot:
        for r in self.robots:
            if r.id == rid:
                return r
        raise KeyError(rid)

    def endpoint(self, use_address: bool = False) -> str:
        """The endpoint robots connect to."""
        proto = "tls" if self.tls.enabled else "tcp"
        host = self.base.address if use_address and self.base.address else self.base.host
        if ":" in host:
            host = f"[{host}]"
        return f"{proto}/{host}:{self.base.port}"

    @property
    def base_roles(self) -> tuple[str, ...]:
        """The base station's processes that join the bus, each with a certificate and
        rights of its own: ``world`` (the simulator), ``laser`` (the LMS bridge, with
        hardware), ``localizer``, ``recorder``."""
        world = {"sim": ("world",), "hardware": ("laser",)}.get(self.base.world, ())
        return (*world, *(("localizer",) if self.base.localizer else ()),
                *(("recorder",) if self.base.recorder else ()))

    def tls_files(self, host: str) -> dict[str, bool]:
        """The files ``host`` needs in the TLS directory, each with whether it is a
        private key: the CA's certificate, and the certificate and key of every identity
        that runs there."""
        t = self.tls
        pairs = []
        if host == self.base.host:
            pairs.append(router_files(0) if self.meshed else (t.base_cert, t.base_key))
            pairs += [t.role_files(role) for role in self.base_roles]
        pairs += [router_files(k) for k, h in enumerate(self.router_hosts) if k and h == host]
        pairs += [(r.cert, r.key) for r in self.robots if r.host == host]
        files = {t.ca: False}
        for cert, key in pairs:
            files.setdefault(cert, False)
            files[key] = True
        return files

    @staticmethod
    def common_name(who: int | str | None, generation: int = 1) -> str:
        """The certificate common name of robot ``who`` (an id) in its ``generation``
        (the first has no suffix, the n-th ``-gN``), of a base station process (a role
        of ``base_roles``), or (None) of the router."""
        if who is None:
            return "btrack-base"
        if isinstance(who, int):
            return f"btrack-robot-{who}" + (f"-g{generation}" if generation > 1 else "")
        return f"btrack-{who}"


# --- loading ---------------------------------------------------------------------------


def _line_of(text: str, path: tuple[str | int, ...]) -> int | None:
    """Best effort: the line of ``path`` (e.g. ("robots", 2, "id")) in the TOML text."""
    lines = text.splitlines()
    start, end = 0, len(lines)
    keys = list(path)
    if keys and isinstance(keys[0], str) and len(keys) >= 2:
        table, rest = keys[0], keys[1:]
        if rest and isinstance(rest[0], int):
            header = re.compile(rf"^\s*\[\[\s*{re.escape(table)}\s*\]\]")
            hits = [i for i, ln in enumerate(lines) if header.match(ln)]
            if rest[0] >= len(hits):
                return None
            start = hits[rest[0]]
            rest = rest[1:]
        else:
            header = re.compile(rf"^\s*\[\s*{re.escape(table)}\s*\]")
            hits = [i for i, ln in enumerate(lines) if header.match(ln)]
            if not hits:
                return None
            start = hits[0]
        nxt = [i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")]
        end = nxt[0] if nxt else len(lines)
        keys = rest
    elif keys:
        nxt = [i for i, ln in enumerate(lines) if ln.lstrip().startswith("[")]
        end = nxt[0] if nxt else len(lines)
    if not keys:
        return start + 1
    key = re.compile(rf"^\s*{re.escape(str(keys[0]))}\s*=")
    for i in range(start, end):
        if key.match(lines[i]):
            return i + 1
    return start + 1 if start else None


class _Reader:
    """Typed access to one table, refusing unknown keys and wrong types by path."""

    def __init__(self, source: str, text: str, data: dict[str, Any], path: tuple[str | int, ...]):
        self.source, self.text, self.data, self.path = source, text, data, path
        self.used: set[str] = set()

    def fail(self, key: str | None, why: str) -> FleetError:
        path = self.path + ((key,) if key is not None else ())
        name = ".".join(f"[{p}]" if isinstance(p, int) else p for p in path).replace(".[", "[")
        line = _line_of(self.text, path)
        where = f"{self.source}:{line}" if line else self.source
        return FleetError(f"{where}: {name or 'top level'}: {why}")

    def get(self, key: str, kind: type, default: Any = ..., check: Any = None) -> Any:
        self.used.add(key)
        if key not in self.data:
            if default is ...:
                raise self.fail(key, "missing (required)")
            return default
        value = self.data[key]
        if kind is float and isinstance(value, int) and not isinstance(value, bool):
            value = float(value)
        if kind is tuple:
            if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
                raise self.fail(key, f"expected a list of strings, got {value!r}")
            value = tuple(value)
        elif not isinstance(value, kind) or (isinstance(value, bool) and kind is not bool):
            raise self.fail(key, f"expected {kind.__name__}, got {value!r}")
        if check is not None:
            problem = check(value)
            if problem:
                raise self.fail(key, problem)
        return value

    def table(self, key: str, required: bool = False) -> _Reader:
        self.used.add(key)
        value = self.data.get(key)
        if value is None:
            if required:
                raise self.fail(key, "missing table (required)")
            value = {}
        if not isinstance(value, dict):
            raise self.fail(key, "expected a table")
        return _Reader(self.source, self.text, value, self.path + (key,))

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            raise self.fail(unknown[0], f"unknown key; known here: {', '.join(sorted(self.used))}")


def _host(value: str) -> str | None:
    return None if _HOST_RE.match(value) else "not a host name or address"


def _file(value: str) -> str | None:
    return None if _FILE_RE.match(value) else "a plain file name (no directories)"


def _abs(value: str) -> str | None:
    return None if value.startswith("/") else "must be an absolute path"


def _positive(value: float) -> str | None:
    return None if value > 0 else "must be positive"


def parse(text: str, source: str = "fleet.toml") -> Fleet:
    """A Fleet from the text of a fleet file; FleetError names what is wrong."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise FleetError(f"{source}: not valid TOML: {exc}") from None
    top = _Reader(source, text, data, ())
    namespace = top.get("namespace", str, check=lambda v: None if _NS_RE.match(v) else
                        "letters, digits, '-', '_' and '/' separators only")
    btrack = top.get("btrack", str, "/opt/btrack/.venv/bin/btrack", check=_abs)
    config_dir = top.get("config_dir", str, "/etc/btrack", check=_abs)
    user = top.get("user", str, "btrack",
                   check=lambda v: None if re.match(r"^[a-z_][a-z0-9_\-]*$", v) else
                   "not a user name")
    lease_s = top.get("lease_s", float, 1.0, check=_positive)
    agent_args = top.get("agent_args", tuple, ())
    epoch = top.get("epoch", float, None, check=lambda v: None if math.isfinite(v) and v >= 0
                    else "must be Unix seconds (date +%s)")
    bridge_args = top.get("bridge_args", tuple, ())

    b = top.table("base", required=True)
    base = Base(
        host=b.get("host", str, check=_host),
        address=b.get("address", str, None, check=_host),
        port=b.get("port", int, 7447,
                   check=lambda v: None if 0 < v < 65536 else "must be in 1..65535"),
        world=b.get("world", str, "sim", check=lambda v: None if v in ("sim", "hardware", "none")
                    else "one of sim, hardware, none"),
        world_args=b.get("world_args", tuple, ()),
        laser_port=b.get("laser_port", str, "/dev/ttyUSB1", check=_abs),
        # with hardware, poses come from the laser: the localizer is on unless refused
        localizer=b.get("localizer", bool, b.data.get("world") == "hardware"),
        localizer_args=b.get("localizer_args", tuple, ()),
        recorder=b.get("recorder", bool, True),
        recorder_dir=b.get("recorder_dir", str, "/var/lib/btrack/runs", check=_abs),
        lease_s=b.get("lease_s", float, lease_s, check=_positive),
    )
    if base.world == "hardware":
        if not base.localizer:
            raise b.fail("localizer", 'world = "hardware" needs the localizer: the robots\' '
                                      "poses come from the laser")
        if epoch is None:
            raise b.fail("world", 'world = "hardware" needs a top-level epoch = UNIX_SECONDS '
                                  "(date +%s, once): every bridge counts ticks from it")
    b.done()

    t = top.table("tls")
    tls = Tls(
        enabled=t.get("enabled", bool, True),
        dir=t.get("dir", str, f"{config_dir}/tls", check=_abs),
        ca=t.get("ca", str, "ca.pem", check=_file),
        base_cert=t.get("base_cert", str, "base.pem", check=_file),
        base_key=t.get("base_key", str, "base.key", check=_file),
        access_control=t.get("access_control", bool, True),
    )
    t.done()
    if tls.access_control and not tls.enabled:
        raise t.fail("access_control", "needs enabled = true (robots are told apart by "
                                       "their certificates)")

    routers = _routers(top, base)
    top.used.add("robots")
    raw = data.get("robots")
    if not isinstance(raw, list) or not raw:
        raise top.fail("robots", "at least one [[robots]] table is required")
    robots: list[Robot] = []
    for n, entry in enumerate(raw):
        if not isinstance(entry, dict):
            raise top.fail("robots", "expected [[robots]] tables")
        r = _Reader(source, text, entry, ("robots", n))
        rid = r.get("id", int, check=lambda v: None if v >= 0 else "must be >= 0")
        robot = Robot(
            id=rid,
            host=r.get("host", str, check=_host),
            cert=r.get("cert", str, f"robot-{rid}.pem", check=_file),
            key=r.get("key", str, f"robot-{rid}.key", check=_file),
            agent_args=r.get("agent_args", tuple, ()),
            port=r.get("port", str, "/dev/ttyUSB0", check=_abs),
            bridge_args=r.get("bridge_args", tuple, ()),
            generation=r.get("generation", int, 1,
                             check=lambda v: None if v >= 1 else "must be >= 1"),
            router=r.get("router", int, 0, check=lambda v: None if 0 <= v <= len(routers) else
                         f"must be 0 (the base station's) .. {len(routers)} (the "
                         f"[[routers]] in order), got {v}"),
        )
        r.done()
        if any(o.id == rid for o in robots):
            raise r.fail("id", f"duplicate robot id {rid}")
        robots.append(robot)
    ids = sorted(r.id for r in robots)
    if ids != list(range(len(ids))):
        raise top.fail("robots", f"robot ids must be 0..{len(ids) - 1}, got {ids}")
    top.done()
    return Fleet(namespace=namespace, base=base, robots=tuple(sorted(robots, key=lambda r: r.id)),
                 tls=tls, btrack=btrack, config_dir=config_dir, user=user, lease_s=lease_s,
                 agent_args=agent_args, epoch=epoch, bridge_args=bridge_args,
                 routers=routers)


def _routers(top: _Reader, base: Base) -> tuple[Router, ...]:
    """The ``[[routers]]`` tables: each host once, none the base station's."""
    top.used.add("routers")
    raw = top.data.get("routers", [])
    if not isinstance(raw, list) or not all(isinstance(e, dict) for e in raw):
        raise top.fail("routers", "expected [[routers]] tables")
    routers: list[Router] = []
    for n, entry in enumerate(raw):
        r = _Reader(top.source, top.text, entry, ("routers", n))
        router = Router(host=r.get("host", str, check=_host),
                        address=r.get("address", str, None, check=_host))
        r.done()
        if router.host in (base.host, *(o.host for o in routers)):
            raise r.fail("host", f"{router.host} has a router already (one per host; the "
                                 "base station's is router 0)")
        routers.append(router)
    return tuple(routers)


def load(path: str | Path) -> Fleet:
    """Read and check a fleet file."""
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as exc:
        raise FleetError(f"{p}: cannot read: {exc.strerror or exc}") from None
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise FleetError(f"{p}:{line}: not UTF-8 text (byte {exc.start}: "
                         f"{raw[exc.start:exc.start + 1]!r}); a fleet file is TOML") from None
    return parse(text, str(p))
