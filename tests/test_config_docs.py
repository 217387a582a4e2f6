"""The README's agent configuration block is the configuration as it is: every key of
every section, with the defaults' values, so a user who copies it changes nothing."""

from __future__ import annotations

import dataclasses
import re
import tomllib
from pathlib import Path

from agent.config import SECTIONS, load

README = Path(__file__).resolve().parent.parent / "README.md"


def readme_defaults() -> str:
    text = README.read_text()
    blocks = re.findall(r"```toml\n(.*?)```", text, flags=re.S)
    found = [b for b in blocks if b.startswith("[gains]")]
    assert len(found) == 1, "the README has one defaults block that starts with [gains]"
    return found[0]


def test_readme_config_block_names_every_key_with_its_default(tmp_path):
    block = readme_defaults()
    data = tomllib.loads(block)
    assert set(data) == set(SECTIONS)
    for name, cls in SECTIONS.items():
        fields = {f.name for f in dataclasses.fields(cls)}
        assert set(data[name]) == fields, (name, fields ^ set(data[name]))
    path = tmp_path / "readme.toml"
    path.write_text(block)
    assert load(path) == load(None)
