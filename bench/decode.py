"""Decode cost per message: the wire codec's validating decode of the lockstep's
messages, against msgspec's typed msgpack decoding of the same bytes into structs
of the same fields, alone and followed by the message's own range checks (if msgspec
is installed; it is not a dependency).

    .venv/bin/python bench/decode.py [--n 20000]

Prints microseconds per message for each type, best of five runs."""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from wire import AgentState, Cmd, Pose, Sense, Tick, decode, encode  # noqa: E402

SAMPLES = {
    "Sense": Sense(12.3, 123, 2, True, False, 0.031, 0.002, 0.0, 6.0, 0.1,
                   [1.2, 0.4, 1.5707], "truth"),
    "Pose": Pose(12.3, 123, 2, 1.2, 0.4, 1.5707, [1e-6, 1e-6, 1e-4], "pf"),
    "Cmd": Cmd(12.3, 123, 2, 0.3, -0.12),
    "AgentState": AgentState(12.3, 123, 2, 2.01, 4.02, 1.1, 1.12, 0.61, 0.3, 1, 1, 3, 0.0,
                             6.0, turns=3.2, end_bins=[20, 21, 39, 40],
                             end_depths=[0.31, 0.29, 0.33, 0.30], cycle_s=180.0, passes=16,
                             need_below=170.0, need_above=175.0, span_below=2.0,
                             span_above=2.1),
    "Tick": Tick(12.3, 123, [0, 1, 2, 3], 1.2),
}


def best_us(fn, payload: bytes, n: int) -> float:
    times = []
    for _ in range(5):
        began = time.perf_counter()
        for _ in range(n):
            fn(payload)
        times.append(time.perf_counter() - began)
    return 1e6 * min(times) / n


def msgspec_decoders():
    """msgspec structs with the same fields and types as each message, or None."""
    try:
        import msgspec
    except ImportError:
        return None
    import dataclasses
    import typing

    out = {}
    for name, msg in SAMPLES.items():
        cls = type(msg)
        hints = typing.get_type_hints(cls)
        fields = []
        for f in dataclasses.fields(cls):
            if f.default is not dataclasses.MISSING:
                fields.append((f.name, hints[f.name], f.default))
            elif f.default_factory is not dataclasses.MISSING:
                fields.append((f.name, hints[f.name], msgspec.field(
                    default_factory=f.default_factory)))
            else:
                fields.append((f.name, hints[f.name]))
        struct = msgspec.defstruct(name, fields, forbid_unknown_fields=True)
        out[name] = msgspec.msgpack.Decoder(struct).decode
    return out


def checked(decode_struct, cls):
    """msgspec's decode, then the message's ``check`` on the struct (it reads fields)."""
    def run(payload: bytes):
        msg = decode_struct(payload)
        cls.check(msg)
        return msg
    return run


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--n", type=int, default=20000, help="decodes per run (20000)")
    args = p.parse_args()
    fast = msgspec_decoders()
    print("| message | bytes | wire.decode (us) | msgspec (us) | msgspec + checks (us) |")
    print("| --- | --- | --- | --- | --- |")
    for name, msg in SAMPLES.items():
        payload = encode(msg)
        cls = type(msg)
        ours = best_us(lambda b, c=cls: decode(c, b), payload, args.n)
        theirs = best_us(fast[name], payload, args.n) if fast else math.nan
        both = best_us(checked(fast[name], cls), payload, args.n) if fast else math.nan
        print(f"| {name} | {len(payload)} | {ours:.1f} | {theirs:.1f} | {both:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
