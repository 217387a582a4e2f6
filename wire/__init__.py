"""The wire contract every btrack process speaks: keys, messages, encoding, sessions.

This package imports nothing else of ours, so any process (or a third-party
tool) can depend on it alone.
"""

from wire.codec import DecodeError, decode, encode
from wire.keys import Keys
from wire.messages import (
    AgentState,
    Cmd,
    Fault,
    Particles,
    Pose,
    Progress,
    Scan,
    Sense,
    Tick,
    Truth,
    WorldInfo,
)

__all__ = [
    "AgentState",
    "Cmd",
    "DecodeError",
    "Fault",
    "Keys",
    "Particles",
    "Pose",
    "Progress",
    "Scan",
    "Sense",
    "Tick",
    "Truth",
    "WorldInfo",
    "decode",
    "encode",
]
