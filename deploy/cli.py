"""``btrack deploy``: a lab's deployment from one fleet file.

``render FLEET.toml --out DIR`` writes every host's files (Zenoh configurations,
environment files, systemd units) under ``DIR/<host>/``; ``certs FLEET.toml --out DIR``
makes a CA and every host's certificates in the same layout. A bad fleet file is
refused with the key (and line) at fault.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

from deploy.fleet import Fleet, FleetError, load


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack deploy",
        description="Deploy a team on real machines from a fleet file (see "
        "deploy/examples/fleet.toml and the README's 'Deploying on a fleet').",
    )
    sub = p.add_subparsers(dest="action", required=True, metavar="ACTION")
    r = sub.add_parser("render", help="write every host's configuration and units",
                       description="Write every host's files under OUT/<host>/, laid out as "
                       "they go on that host, and OUT/INSTALL.md.")
    r.add_argument("fleet", metavar="FLEET.toml")
    r.add_argument("--out", required=True, type=Path, metavar="DIR")
    r.add_argument("--btrack", metavar="PATH",
                   help="absolute path of the btrack command on the hosts "
                   "(overrides the fleet file's btrack)")
    c = sub.add_parser("certs", help="make a CA and every host's certificates (openssl)",
                       description="Make a CA (OUT/ca/, keep it off the hosts) and every "
                       "host's certificate and key under OUT/<host>/<tls dir>/.")
    c.add_argument("fleet", metavar="FLEET.toml")
    c.add_argument("--out", required=True, type=Path, metavar="DIR")
    c.add_argument("--robot", type=int, metavar="ID",
                   help="only robot ID's certificate, again, from the CA already in "
                   "OUT/ca/, for the generation the fleet file gives it (to revoke its "
                   "last one: raise its generation, re-render, restart the router)")
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        fleet = load(args.fleet)
    except FleetError as exc:
        print(f"btrack deploy: {exc}", file=sys.stderr)
        return 2
    if args.action == "render":
        from deploy.render import render, write

        if args.btrack:
            if not args.btrack.startswith("/"):
                print("btrack deploy: --btrack must be an absolute path", file=sys.stderr)
                return 2
            fleet = dataclasses.replace(fleet, btrack=args.btrack)
        written = write(render(fleet), args.out)
        hosts = sorted({p.relative_to(args.out).parts[0] for p in written} - {"INSTALL.md"})
        print(f"btrack deploy: {len(written)} files for {', '.join(hosts)} in {args.out}; "
              f"next steps in {args.out / 'INSTALL.md'}")
        return 0
    from deploy.certs import CertError, make_fleet_certs, reissue_robot_cert

    try:
        if args.robot is not None:
            if args.robot not in {r.id for r in fleet.robots}:
                print(f"btrack deploy: no robot {args.robot} in {args.fleet}", file=sys.stderr)
                return 2
            written = reissue_robot_cert(fleet, args.out, args.robot)
            r = fleet.robot(args.robot)
            print(f"btrack deploy: robot {r.id}'s certificate, generation {r.generation} "
                  f"({Fleet.common_name(r.id, r.generation)}), in {written[0].parent}")
            return 0
        written = make_fleet_certs(fleet, args.out)
    except CertError as exc:
        print(f"btrack deploy: {exc}", file=sys.stderr)
        return 1
    print(f"btrack deploy: {len(written)} certificate files in {args.out} "
          f"(the CA key stays in {args.out / 'ca'})")
    return 0
