"""Reading rendered systemd units as systemd would, for tests: a unit's environment
(its EnvironmentFile=s), its command line (ExecStart= with %i and the environment
expanded by systemd's rules) and the files its process reads."""

from __future__ import annotations

import re
import shlex

import json5

from deploy.render import UNIT_DIR


def host_files(files: dict[str, str], host: str) -> dict[str, str]:
    """The rendered files of ``host`` by their path on it."""
    return {"/" + k.split("/", 1)[1]: v for k, v in files.items() if k.startswith(host + "/")}


def _unit_text(files: dict[str, str], host: str, unit: str, instance: str) -> str:
    text = host_files(files, host)[f"/{UNIT_DIR}/{unit}"]
    return text.replace("%i", instance)


def environment_files(files: dict[str, str], host: str, unit: str,
                      instance: str = "") -> list[str]:
    return re.findall(r"^EnvironmentFile=(\S+)$", _unit_text(files, host, unit, instance), re.M)


def environment(files: dict[str, str], host: str, unit: str, instance: str = ""
                ) -> dict[str, str]:
    mine, env = host_files(files, host), {}
    for path in environment_files(files, host, unit, instance):
        for line in mine[path].splitlines():
            if "=" in line and not line.startswith("#"):
                key, value = line.split("=", 1)
                env[key] = value
    return env


def exec_argv(files: dict[str, str], host: str, unit: str, instance: str = "") -> list[str]:
    """The unit's ExecStart= as systemd runs it: ``${VAR}`` is one word, ``$VAR`` is
    split at white space, ``%i`` is the instance."""
    found = re.search(r"^ExecStart=(.*)$", _unit_text(files, host, unit, instance), re.M)
    assert found, unit
    env = environment(files, host, unit, instance)
    argv: list[str] = []
    for word in shlex.split(found.group(1)):
        whole = re.fullmatch(r"\$(\w+)", word)
        if whole:
            argv += env.get(whole.group(1), "").split()
        else:
            argv.append(re.sub(r"\$\{(\w+)\}", lambda m: env[m.group(1)], word))
    return argv


def zenoh_config_of(files: dict[str, str], host: str, unit: str, instance: str = "") -> str:
    """The Zenoh configuration the unit's process opens its session with."""
    argv = exec_argv(files, host, unit, instance)
    if "--zenoh-config" in argv:
        return argv[argv.index("--zenoh-config") + 1]
    return environment(files, host, unit, instance)["ZENOH_CONFIG"]


def reads(files: dict[str, str], host: str, unit: str, instance: str = "") -> set[str]:
    """The files the unit's process must read: its environment files, its Zenoh
    configuration and the certificates and keys that configuration names."""
    config = zenoh_config_of(files, host, unit, instance)
    conf = json5.loads(host_files(files, host)[config])
    tls = conf.get("transport", {}).get("link", {}).get("tls", {})
    return {*environment_files(files, host, unit, instance), config,
            *(v for k, v in tls.items() if k.endswith(("certificate", "private_key")))}
