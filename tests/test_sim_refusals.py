"""``btrack sim`` refuses what cannot run, by name and before it starts a process
(issue 19, item 6): each case here was a traceback or a run that went silently wrong."""

from __future__ import annotations

import signal
import struct
import zlib
from pathlib import Path

import pytest

from deploy import launcher
from tests.procutil import run_sim, taken_port


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


def test_hardware_faults_need_the_hardware_loop(tmp_path, capsys):
    out = tmp_path / "run"
    code = launcher.main(["--out", str(out), "--duration", "5", "--quiet", "--no-report",
                          "--hil-faults", "0.1"])
    assert code == 2
    assert "--hil-faults needs --hil" in capsys.readouterr().err
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


# Issue 22, item 2: every option of ``btrack sim`` under --hil either changes what the
# hardware loop does (its plan, which is all that ``hil.run`` reads) or is refused by
# name. A new option lands in none of these tables and fails the first test below.
HIL_REFUSED = {
    "fault": ["--fault", "kill:1@60"],
    "chaos": ["--chaos", "3"],
    "kidnap": ["--kidnap", "1@2:0.1,0"],
    "odom_noise": ["--odom-noise", "0.1"],
    "odom_turn_noise": ["--odom-turn-noise", "0.1"],
    "boot_s": ["--boot-s", "2"],
    "scanners": ["--scanners", "2"],
    "sensors": ["--sensors", "lab"],
    "clouds_every": ["--clouds-every", "5"],
    "live": ["--live"],
    "engine": ["--engine", "inprocess"],
    "change": ["--change", "grow:0.5@10-20"],
    "agents": ["--agents", "client"],
}
HIL_PLANNED = {
    "robots": ["--robots", "2"],
    "map": ["--map", "no-algae"],
    "scale": ["--scale", "0.04"],
    "start": ["--start", "in-phase"],
    "duration": ["--duration", "7"],
    "seed": ["--seed", "2"],
    "out": ["--out", "elsewhere"],
    "config": ["--config", "agent.toml"],
    "k_s": ["--k-s", "0.01"],
    "k_phi": ["--k-phi", "0.2"],
    "cycle_s": ["--cycle-s", "150"],
    "passes": ["--passes", "3"],
    "ns": ["--ns", "hil/other"],
    "port": ["--port", "7999"],
    "no_report": ["--no-report"],
    "no_scene": ["--no-scene"],
    "quiet": ["--quiet"],
    "progress_every": ["--progress-every", "3"],
    "hil_faults": ["--hil-faults", "0.1"],
    "localization": ["--localization", "truth"],
}
HIL_ITSELF = {
    "hil": "the mode",
    "realtime": "the hardware loop is paced on the wall clock with or without it",
}


def _hil_args(tmp_path: Path, *argv: str):
    (tmp_path / "agent.toml").write_text("")
    args = launcher.build_parser().parse_args(
        ["--hil", "--out", str(tmp_path / "run"), "--ns", "hil/test", "--port", "7998",
         "--duration", "5", *argv])
    if args.config is not None:
        args.config = str(tmp_path / args.config)
    if args.out.name == "elsewhere":
        args.out = tmp_path / "elsewhere"
    return args


def test_every_option_is_either_refused_or_planned_with_hil():
    dests = {a.dest for a in launcher.build_parser()._actions if a.dest != "help"}
    tables = [set(HIL_REFUSED), set(HIL_PLANNED), set(HIL_ITSELF)]
    assert sum(map(len, tables)) == len(set().union(*tables)), "an option in two tables"
    assert dests == set().union(*tables)


@pytest.mark.parametrize("dest", sorted(HIL_REFUSED))
def test_an_option_the_hardware_loop_cannot_follow_is_refused_by_name(tmp_path, capsys, dest):
    out = tmp_path / "run"
    code = launcher.main(["--hil", "--out", str(out), "--duration", "90", "--quiet",
                          *HIL_REFUSED[dest]])
    err = capsys.readouterr().err
    assert code == 2, err
    assert f"{HIL_REFUSED[dest][0]}" in err and "not with --hil" in err
    assert "Traceback" not in err
    assert not (out / "logs").exists()


@pytest.mark.parametrize("dest", sorted(HIL_PLANNED))
def test_an_option_the_hardware_loop_follows_changes_its_plan(tmp_path, dest):
    from hwbridge import hil

    base, given = _hil_args(tmp_path), _hil_args(tmp_path, *HIL_PLANNED[dest])
    assert launcher.hil_refusal(given) is None
    assert launcher.refusal(given, given.robots) is None
    assert hil.plan(given, 1.0e9) != hil.plan(base, 1.0e9)


def test_the_hardware_loop_runs_on_the_filter_or_on_truth_never_on_dead_reckoning(tmp_path):
    from hwbridge import hil

    for given in ((), ("--localization", "pf")):
        args = _hil_args(tmp_path, *given)
        assert launcher.hil_refusal(args) is None
        commands = hil.plan(args, 1.0e9).commands
        assert commands["localizer"][:2] == ["localizer", "--robots"]
        assert "measured" in commands["localizer"]
    truth = hil.plan(_hil_args(tmp_path, "--localization", "truth"), 1.0e9).commands
    assert "localizer" not in truth
    assert truth["hil-world"][truth["hil-world"].index("--localization") + 1] == "truth"
    assert "--localization odometry" in (
        launcher.hil_refusal(_hil_args(tmp_path, "--localization", "odometry")) or "")


def test_unstable_gains_are_refused_before_the_hardware_loop_starts(tmp_path, capsys):
    out = tmp_path / "run"
    code = launcher.main(["--hil", "--out", str(out), "--k-phi", "0.7", "--quiet"])
    assert code == 2
    assert "unstable gains" in capsys.readouterr().err
    assert not (out / "logs").exists()


def test_the_hardware_loop_with_a_fault_exits_2_naming_it(tmp_path):
    """``btrack sim --hil --fault kill:1@60`` (issue 22): refused, as the command."""
    result = run_sim(tmp_path / "run", "--hil", "--fault", "kill:1@60", timeout=60)
    assert result.returncode == 2, result.stderr
    assert "--fault: not with --hil" in result.stderr
    assert "Traceback" not in result.stderr


def test_a_port_something_listens_on_is_refused_before_a_process_starts(tmp_path, capsys):
    """It was a run whose recorder died on the taken port while the others waited 60 s
    on a listener that speaks no Zenoh; the launcher now refuses it by name."""
    with taken_port() as port:
        err = _refused(tmp_path, capsys, "--port", str(port))
    assert f"--port {port}: something already listens on loopback port {port}" in err
