"""Which message type a topic carries, and the JSON schema of each type's channel."""

from __future__ import annotations

import dataclasses
import json
import typing
from functools import cache
from typing import Any

from wire.keys import parse_path

INVALID_PREFIX = "invalid/"
REJECTED_PREFIX = "rejected/"  # well formed but implausible (forged or broken): see writer
ALIVE_PREFIX = "alive/agent/"

def message_type(topic: str) -> type | None:
    """The message class on ``topic`` (a key without the namespace), or None if unknown
    or a key that carries no message (the contract's table, ``wire.keys.TOPICS``)."""
    found = parse_path(topic)
    return found[0].message if found else None


_JSON_TYPES: dict[Any, dict[str, Any]] = {
    float: {"type": "number"},
    int: {"type": "integer"},
    bool: {"type": "boolean"},
    str: {"type": "string"},
}


def _json_type(hint: Any) -> dict[str, Any]:
    if hint in _JSON_TYPES:
        return dict(_JSON_TYPES[hint])
    if typing.get_origin(hint) is list:
        (item,) = typing.get_args(hint)
        return {"type": "array", "items": _json_type(item)}
    return {}


@cache
def schema_of(cls: type) -> bytes:
    """A JSON schema (draft 2020-12) for the JSON form of message class ``cls``."""
    hints = typing.get_type_hints(cls)
    fields = dataclasses.fields(cls)
    schema = {
        "$schema": "https://json-schema.org/draft/2020-12/schema",
        "title": cls.__name__,
        "description": (cls.__doc__ or "").strip().splitlines()[0] if cls.__doc__ else "",
        "type": "object",
        "properties": {f.name: _json_type(hints[f.name]) for f in fields},
        "required": [
            f.name
            for f in fields
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        ],
    }
    return json.dumps(schema).encode()


INVALID_SCHEMA = json.dumps(
    {
        "title": "Invalid",
        "description": "A payload that failed to decode: the reason and its first 64 bytes",
        "type": "object",
        "properties": {"error": {"type": "string"}, "hex": {"type": "string"}},
        "required": ["error", "hex"],
    }
).encode()

ALIVE_SCHEMA = json.dumps(
    {
        "title": "Alive",
        "description": "A liveliness token appeared (true) or went away (false)",
        "type": "object",
        "properties": {"alive": {"type": "boolean"}},
        "required": ["alive"],
    }
).encode()

GENERIC_SCHEMA = json.dumps(
    {"title": "Unknown", "description": "A msgpack map on a topic of no known type"}
).encode()
