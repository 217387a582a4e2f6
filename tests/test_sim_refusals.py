"""``btrack sim`` refuses what cannot run, by name and before it starts a process
(issue 19, item 6): each case here was a traceback or a run that went silently wrong."""

from __future__ import annotations

import signal
import struct
import zlib
from pathlib import Path

import pytest

from deploy import launcher
from tests.procutil import run_sim


@pytest.fixture(autouse=True)
def _keep_sigterm():
    """``launcher.main`` turns SIGTERM into an exception for its run; give pytest its own
    handler back."""
    before = signal.getsignal(signal.SIGTERM)
    yield
    signal.signal(signal.SIGTERM, before)


def _png_header_only(path: Path, width: int, height: int) -> None:
    """A PNG whose header claims width x height pixels and holds no image data: what a
    reader learns before it decodes anything."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b""))


def _refused(tmp_path: Path, capsys: pytest.CaptureFixture[str], *argv: str) -> str:
    out = tmp_path / "run"
    code = launcher.main(["--out", str(out), "--localization", "truth", "--duration", "5",
                          "--quiet", "--no-report", *argv])
    err = capsys.readouterr().err
    assert code == 2, err
    assert not (out / "logs").exists(), "a process was started"
    return err


@pytest.mark.parametrize(("argv", "expected"), [
    (["--robots", "0"], "--robots must be between 1 and 100, not 0"),
    (["--robots", "-1"], "--robots must be between 1 and 100, not -1"),
    (["--robots", "200"], "--robots must be between 1 and 100, not 200"),
    (["--ns", "a b/*"], "--ns: bad namespace 'a b/*'"),
    (["--duration", "nan"], "--duration must be a positive number"),
    (["--fault", "kill:1@50"], "--fault kill:1@50 would come after the run's end"),
    (["--robots", "50"], "50 robots need 7.50 m of edge at min_segment_m = 0.15 m"),
    (["--robots", "39", "--fault", "join:39@1", "--fault", "join:40@2"],
     "41 robots need 6.15 m of edge"),
    (["--map", "no-such-map"], "--map: unknown map 'no-such-map'"),
    (["--scanners", "0"], "--scanners must be between 1 and 16, not 0"),
    (["--scanners", "2", "--localization", "truth"], "--scanners: the laser scans only"),
    (["--clouds-every", "0"], "--clouds-every must be at least 1, not 0"),
    (["--clouds-every", "5", "--localization", "odometry"],
     "--clouds-every: particles come from the localizer"),
    (["--live", "70000"], "--live must be a port between 1 and 65535, not 70000"),
])
def test_sim_refuses_by_name_before_starting_anything(tmp_path, capsys, argv, expected):
    assert expected in _refused(tmp_path, capsys, *argv)


@pytest.mark.parametrize(("argv", "expected"), [
    (["--hil", "--fault", "kill:1@3"], "--fault: not with --hil"),
    (["--hil", "--chaos", "3"], "--chaos: not with --hil"),
    (["--hil", "--kidnap", "1@2:0.1,0"], "--kidnap: not with --hil"),
    (["--hil", "--odom-noise", "0.1"], "--odom-noise: not with --hil"),
    (["--hil", "--localization", "pf"], "--localization pf: not with --hil"),
    (["--hil", "--boot-s", "2"], "--boot-s: not with --hil"),
    (["--hil", "--scanners", "2"], "--scanners: not with --hil"),
    (["--hil", "--clouds-every", "5"], "--clouds-every: not with --hil"),
    (["--hil", "--live"], "--live: not with --hil"),
    (["--hil-faults", "0.1"], "--hil-faults needs --hil"),
])
def test_options_the_hardware_loop_would_ignore_are_refused_by_name(tmp_path, capsys, argv,
                                                                    expected):
    """Issue 22, item 2: --hil ran the hardware stack and ignored these silently."""
    out = tmp_path / "run"
    code = launcher.main(["--out", str(out), "--duration", "5", "--quiet", "--no-report",
                          *argv])
    err = capsys.readouterr().err
    assert code == 2, err
    assert expected in err
    assert not (out / "logs").exists()


def test_sim_refuses_an_output_directory_it_cannot_write(tmp_path, capsys):
    blocker = tmp_path / "a-file"
    blocker.write_text("")
    out = blocker / "x"
    code = launcher.main(["--out", str(out), "--duration", "5", "--quiet"])
    assert code == 2
    assert f"--out {out}: cannot write there" in capsys.readouterr().err


def test_sim_refuses_a_huge_map_image_from_its_header(tmp_path, capsys):
    big = tmp_path / "big.png"
    _png_header_only(big, 12000, 12000)
    err = _refused(tmp_path, capsys, "--map", str(big))
    assert "12000 x 12000 px (144 M pixels); at most 25 M" in err


@pytest.mark.parametrize(("toml", "expected"), [
    ("[limits]\nv_max = -1\n", "v_max must be a positive speed, not -1 m/s"),
    ("[limits]\nwheel_base_m = 0.0\n", "wheel_base_m must be positive"),
    ("[gains]\nk_s = nan\n", "[gains].k_s: expected a finite number, got nan"),
    ("[patrol]\nmeasure_speed = inf\n", "[patrol].measure_speed: expected a finite number"),
])
def test_sim_refuses_a_config_that_would_run_silently_wrong(tmp_path, capsys, toml, expected):
    cfg = tmp_path / "agent.toml"
    cfg.write_text(toml)
    assert expected in _refused(tmp_path, capsys, "--config", str(cfg))


def test_the_command_itself_exits_2_without_a_traceback(tmp_path):
    result = run_sim(tmp_path / "run", "--robots", "0", timeout=60)
    assert result.returncode == 2
    assert "--robots must be between 1 and 100" in result.stderr
    assert "Traceback" not in result.stderr
