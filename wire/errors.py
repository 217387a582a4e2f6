"""Errors of the wire layer that a command reports as one line, not a traceback.

Kept apart from ``wire.session`` so that ``btrack`` can catch them without importing
Zenoh for commands that never open a bus."""

from __future__ import annotations


class BusError(RuntimeError):
    """The bus could not be opened: an endpoint already in use, a router that did not
    answer within the wait, a configuration Zenoh refuses. The message says which."""
