"""Where a process's listening port comes from, and how a bus that cannot open is told."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import zenoh

from deploy.procs import EPHEMERAL_RANGE, LISTEN_PORTS_FROM, bindable, ephemeral_low, free_port
from tests.procutil import taken_port
from wire.errors import BusError
from wire.session import SessionOptions, open_session, readable


def test_the_ephemeral_range_is_read_from_its_file(tmp_path: Path) -> None:
    good = tmp_path / "range"
    good.write_text("32768\t60999\n")
    assert ephemeral_low(good) == 32768
    bad = tmp_path / "bad"
    bad.write_text("not a port\n")
    assert ephemeral_low(bad) is None
    assert ephemeral_low(tmp_path / "missing") is None


def test_a_free_port_is_drawn_under_the_ephemeral_range_and_is_free() -> None:
    """An outgoing connection takes its port from the ephemeral range; a port drawn
    there could be taken before our listener binds it (a recorder test failed so)."""
    low = ephemeral_low()
    ports = {free_port() for _ in range(20)}
    for port in ports:
        assert bindable(port)
        if low is not None and EPHEMERAL_RANGE.exists() and low - LISTEN_PORTS_FROM >= 1000:
            assert LISTEN_PORTS_FROM <= port < low
    assert len(ports) > 1  # drawn, not one fixed port


def test_a_port_being_listened_on_is_not_bindable() -> None:
    with taken_port() as port:
        assert not bindable(port)


def test_a_listener_on_a_taken_port_is_a_bus_error_without_rust_locations() -> None:
    with taken_port() as port:
        opts = SessionOptions(ns="btrack/test-ports", listen=(f"tcp/127.0.0.1:{port}",),
                              multicast=False)
        try:
            open_session(opts).close()
        except BusError as exc:
            text = str(exc)
            assert isinstance(exc.__cause__, zenoh.ZError)
        else:
            raise AssertionError("a session listened on a port already listened on")
    assert text.startswith("cannot open the bus:")
    assert f"127.0.0.1:{port}" in text and "Address already in use" in text
    assert ".rs:" not in text


def test_readable_drops_only_source_locations() -> None:
    raw = ("Can not create a listener: [x: Address in use (os error 98) at "
           "/root/.cargo/git/a/io/tcp.rs:61.] at /root/.cargo/b/unicast.rs:338.")
    assert readable(RuntimeError(raw)) == (
        "Can not create a listener: [x: Address in use (os error 98)]")


def test_a_router_on_a_taken_port_says_so_in_one_line() -> None:
    with taken_port() as port:
        done = subprocess.run([sys.executable, "-m", "btrack", "router", "--mode", "router",
                               "--listen", f"tcp/127.0.0.1:{port}", "--no-multicast"],
                              capture_output=True, text=True, timeout=60)
    assert done.returncode == 1
    assert done.stderr.startswith("btrack router: cannot open the bus:"), done.stderr
    assert f"127.0.0.1:{port}" in done.stderr and "Traceback" not in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and "cannot start" not in done.stderr
