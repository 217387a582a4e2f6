"""A certificate authority and the certificates a fleet needs, made with the
``openssl`` command (``btrack deploy certs``; the tests use it in a temp dir).

The router's certificate (common name ``btrack-base``) names the base station's
host, its address and localhost, since clients check the router's name (in a mesh
of routers, router K's is ``btrack-router-K`` and names its own host); each base
station process has its own (``btrack-world``, ``btrack-laser``, ``btrack-localizer``,
``btrack-recorder``) and robot i its (``btrack-robot-I``): the common name is what the
router's access control grants rights to.
Good enough for a lab and for tests; a site with its own PKI issues the same
names from it instead.
"""

from __future__ import annotations

import ipaddress
import os
import secrets
import shutil
import subprocess
import tempfile
from datetime import UTC, datetime, timedelta
from pathlib import Path

from deploy.fleet import Fleet, router_common_name, router_files

CURVE = "prime256v1"


class CertError(RuntimeError):
    pass


def _openssl(*args: str) -> None:
    exe = shutil.which("openssl")
    if exe is None:
        raise CertError("the openssl command is needed to make certificates")
    proc = subprocess.run([exe, *args], capture_output=True, text=True)
    if proc.returncode != 0:
        raise CertError(f"openssl {args[0]} failed: {proc.stderr.strip()[-500:]}")


def make_ca(out: Path, name: str = "btrack fleet CA", days: int = 3650) -> tuple[Path, Path]:
    """A self-signed CA: (certificate, private key) in ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    pem, key = out / "ca.pem", out / "ca.key"
    _openssl("req", "-x509", "-newkey", "ec", "-pkeyopt", f"ec_paramgen_curve:{CURVE}",
             "-nodes", "-keyout", str(key), "-out", str(pem), "-days", str(days),
             "-subj", f"/CN={name}",
             "-addext", "basicConstraints=critical,CA:TRUE",
             "-addext", "keyUsage=critical,keyCertSign,cRLSign")
    os.chmod(key, 0o600)
    return pem, key


# `openssl ca` is the one of openssl 3.0's commands that sets an end date to the second
_CA_CONF = """[ca]
default_ca = short
[short]
database = {dir}/index.txt
new_certs_dir = {dir}
serial = {dir}/serial
default_md = sha256
policy = anything
[anything]
commonName = supplied
"""


def make_cert(ca: tuple[Path, Path], pem: Path, key: Path, common_name: str,
              names: tuple[str, ...] = (), days: int = 825,
              not_after: datetime | None = None) -> None:
    """A certificate signed by ``ca`` for ``common_name``, usable both as a TLS
    server and a client; ``names`` (host names or IP addresses) go in its
    subjectAltName. It is valid for ``days``, or until ``not_after`` (to the second:
    tests of expiry)."""
    pem.parent.mkdir(parents=True, exist_ok=True)
    key.parent.mkdir(parents=True, exist_ok=True)
    alt = []
    for n in dict.fromkeys(names):
        try:
            ipaddress.ip_address(n)
            alt.append(f"IP:{n}")
        except ValueError:
            alt.append(f"DNS:{n}")
    ext = ["basicConstraints=critical,CA:FALSE",
           "keyUsage=critical,digitalSignature,keyEncipherment",
           "extendedKeyUsage=serverAuth,clientAuth"]
    if alt:
        ext.append("subjectAltName=" + ",".join(alt))
    with tempfile.TemporaryDirectory() as tmp:
        csr, extfile = Path(tmp) / "req.csr", Path(tmp) / "ext.cnf"
        extfile.write_text("\n".join(ext) + "\n")
        _openssl("req", "-new", "-newkey", "ec", "-pkeyopt", f"ec_paramgen_curve:{CURVE}",
                 "-nodes", "-keyout", str(key), "-out", str(csr), "-subj", f"/CN={common_name}")
        if not_after is None:
            _openssl("x509", "-req", "-in", str(csr), "-CA", str(ca[0]), "-CAkey", str(ca[1]),
                     "-set_serial", str(secrets.randbits(63)), "-days", str(days),
                     "-extfile", str(extfile), "-out", str(pem))
        else:
            conf = Path(tmp) / "ca.cnf"
            conf.write_text(_CA_CONF.format(dir=tmp))
            (Path(tmp) / "index.txt").write_text("")
            (Path(tmp) / "serial").write_text(f"{secrets.randbits(63):016X}\n")
            stamp = "%y%m%d%H%M%SZ"
            start = datetime.now(UTC) - timedelta(minutes=1)
            _openssl("ca", "-batch", "-notext", "-config", str(conf), "-cert", str(ca[0]),
                     "-keyfile", str(ca[1]), "-in", str(csr), "-out", str(pem),
                     "-extfile", str(extfile), "-startdate", start.strftime(stamp),
                     "-enddate", not_after.astimezone(UTC).strftime(stamp))
    os.chmod(key, 0o600)


def make_fleet_certs(fleet: Fleet, out: Path, flat: bool = False) -> list[Path]:
    """A CA (kept in ``out/ca/``, never copied to a host) and every host's
    certificates under ``out/<host>/<tls dir>/``, beside ``btrack deploy render``'s
    tree, or (``flat``, for tests on one machine) all in ``out/``. Returns the files
    written."""
    ca = make_ca(out / "ca")
    tls = fleet.tls
    written = [*ca]

    def host_dir(host: str) -> Path:
        d = out if flat else out / host / tls.dir.strip("/")
        d.mkdir(parents=True, exist_ok=True)
        shutil.copy(ca[0], d / tls.ca)
        return d

    sites = [(fleet.base.host, fleet.base.address),
             *((r.host, r.address) for r in fleet.routers)]
    for k, (host, address) in enumerate(sites):  # the routers: a mesh's are router-K
        d = host_dir(host)
        names = tuple(n for n in (host, address, "localhost", "127.0.0.1") if n)
        pem, key = (router_files(k) if fleet.meshed else (tls.base_cert, tls.base_key))
        name = router_common_name(k) if fleet.meshed else Fleet.common_name(None)
        make_cert(ca, d / pem, d / key, name, names)
        written += [d / tls.ca, d / pem, d / key]
    d = host_dir(fleet.base.host)
    for role in fleet.base_roles:  # a client certificate each: its name is its rights
        pem, key = tls.role_files(role)
        make_cert(ca, d / pem, d / key, Fleet.common_name(role))
        written += [d / pem, d / key]
    for r in fleet.robots:
        d = host_dir(r.host)
        make_cert(ca, d / r.cert, d / r.key, Fleet.common_name(r.id, r.generation), (r.host,))
        written += [d / tls.ca, d / r.cert, d / r.key]
    return written


def reissue_robot_cert(fleet: Fleet, out: Path, rid: int, flat: bool = False) -> list[Path]:
    """Robot ``rid``'s certificate again, from the CA ``make_fleet_certs`` left in
    ``out/ca/``, under the common name of its generation in ``fleet``: after raising
    the robot's ``generation`` (to revoke a stolen or lost key), this is the only
    certificate of that robot the re-rendered router accepts."""
    ca = (out / "ca" / "ca.pem", out / "ca" / "ca.key")
    if not ca[0].is_file() or not ca[1].is_file():
        raise CertError(f"no CA in {out / 'ca'}: make the fleet's certificates first")
    r = fleet.robot(rid)
    d = out if flat else out / r.host / fleet.tls.dir.strip("/")
    d.mkdir(parents=True, exist_ok=True)
    make_cert(ca, d / r.cert, d / r.key, Fleet.common_name(r.id, r.generation), (r.host,))
    return [d / r.cert, d / r.key]
