"""msgpack encoding of the message dataclasses, with validation on decode.

Decoding never raises anything but ``DecodeError``: wrong type, missing or extra
field, NaN or infinity, or a range rule of the message (its ``check``) all end there,
so a process counts and drops the message and keeps running.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from functools import cache
from typing import Any, TypeVar

import msgpack

from wire.messages import InvalidMessage

T = TypeVar("T")

MSGPACK = "application/msgpack"


class DecodeError(ValueError):
    """A payload that is not a valid message of the expected type."""


@cache
def _names(cls: Any) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls))


def encode(msg: Any) -> bytes:
    """The msgpack bytes of a message dataclass (a map of field name to value)."""
    kind: Any = type(msg)
    return msgpack.packb({n: getattr(msg, n) for n in _names(kind)}, use_bin_type=True)


@cache
def _field_types(cls: Any) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)}


@cache
def _required(cls: Any) -> frozenset[str]:
    return frozenset(
        f.name
        for f in dataclasses.fields(cls)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    )


def _coerce(name: str, value: Any, hint: Any) -> Any:
    if hint is float and type(value) is float:  # the common case, checked cheaply
        if value - value != 0.0:  # NaN or infinity
            raise DecodeError(f"{name}: not finite ({value})")
        return value
    if hint is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise DecodeError(f"{name}: expected a number, got {type(value).__name__}")
        value = float(value)
        if not math.isfinite(value):
            raise DecodeError(f"{name}: not finite ({value})")
        return value
    if hint is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise DecodeError(f"{name}: expected an integer, got {type(value).__name__}")
        return value
    if hint is bool:
        if not isinstance(value, bool):
            raise DecodeError(f"{name}: expected a boolean, got {type(value).__name__}")
        return value
    if hint is str:
        if not isinstance(value, str):
            raise DecodeError(f"{name}: expected a string, got {type(value).__name__}")
        return value
    origin = typing.get_origin(hint)
    if origin is list:
        (item,) = typing.get_args(hint)
        if not isinstance(value, (list, tuple)):
            raise DecodeError(f"{name}: expected a list, got {type(value).__name__}")
        if item is float and all(type(v) is float and v - v == 0.0 for v in value):
            return list(value)  # the common case (a scan's ranges), checked cheaply
        return [_coerce(f"{name}[{i}]", v, item) for i, v in enumerate(value)]
    raise DecodeError(f"{name}: unsupported field type {hint}")  # pragma: no cover


@cache
def _plan(cls: Any) -> tuple[tuple[tuple[str, Any], ...], frozenset[str]]:
    """The fields of ``cls`` with their type hints, in order, and their names."""
    types = _field_types(cls)
    return tuple(types.items()), frozenset(types)


def decode(cls: type[T], payload: bytes) -> T:
    """Decode and validate ``payload`` as a ``cls`` message, or raise ``DecodeError``."""
    try:
        raw = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises several unrelated types on garbage
        raise DecodeError(f"not msgpack: {exc}") from None
    return from_mapping(cls, raw)


def from_mapping(cls: type[T], raw: Any) -> T:
    """Validate a decoded map (msgpack's, or a recording's JSON) as a ``cls`` message,
    as ``decode`` does, or raise ``DecodeError``."""
    if not isinstance(raw, dict):
        raise DecodeError(f"expected a map, got {type(raw).__name__}")
    spec: Any = cls  # a dataclass type, hashable for the caches
    plan, names = _plan(spec)
    if raw.keys() != names:  # the common case skips both set differences
        missing = _required(spec) - raw.keys()
        if missing:
            raise DecodeError(f"missing field(s): {', '.join(sorted(missing))}")
        extra = raw.keys() - names
        if extra:
            raise DecodeError(f"unknown field(s): {', '.join(sorted(map(str, extra)))}")
    values = {}
    for name, hint in plan:
        if name not in raw:
            continue  # an optional field: its default
        value = raw[name]
        kind = type(value)
        # the common cases inline (finite float, plain int); everything else in _coerce
        if (kind is float and hint is float and value - value == 0.0) or (
            kind is int and hint is int
        ):
            values[name] = value
        else:
            values[name] = _coerce(name, value, hint)
    msg = cls(**values)
    try:
        msg.check()  # type: ignore[attr-defined]
    except InvalidMessage as exc:
        raise DecodeError(str(exc)) from None
    return msg


def from_record(cls: type[T], raw: Any) -> T:
    """A message as recorded (a map the recorder had validated as ``cls`` when it
    arrived): the dataclass, its fields by name, without validating each value again.
    A map with a field ``cls`` does not have, or without one it needs, raises
    ``DecodeError`` (a recording of an older or newer contract)."""
    if not isinstance(raw, dict):
        raise DecodeError(f"expected a map, got {type(raw).__name__}")
    spec: Any = cls
    names = _plan(spec)[1]
    if raw.keys() != names:
        missing = _required(spec) - raw.keys()
        extra = raw.keys() - names
        if missing or extra:
            raise DecodeError(f"fields not of {cls.__name__}: missing {sorted(missing)}, "
                              f"unknown {sorted(map(str, extra))}")
    return cls(**raw)
