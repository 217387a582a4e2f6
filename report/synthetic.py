"""A synthetic recorded run (idealised lawnmower tracks), written through the recorder's
own code path, for tests and for trying the report without a simulator."""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from recorder.writer import Recording, RunWriter
from wire.codec import encode
from wire.messages import AgentState, Pose, Tick, Truth, WorldInfo

TWO_PI = 2.0 * math.pi


def synthetic_messages(
    duration_s: float = 60.0,
    dt: float = 0.1,
    robots: int = 3,
    edge: tuple[float, float] = (0.0, 6.0),
    cycle_s: float = 20.0,
    phase_offsets: tuple[float, ...] = (0.0, 2 * math.pi / 5, 0.0),
    settle_s: float = 8.0,
    speedup: float = 100.0,
    garbage: int = 0,
    phase_bias: tuple[float, ...] = (0.0,),
    hardware: bool = False,
    edge_wave_m: float = 0.0,
) -> Iterator[tuple[str, bytes, int]]:
    """The messages of a synthetic run in the order a recorder would get them: (topic,
    payload, wall clock ns). Each robot sweeps its equal segment in ``cycle_s`` with
    a phase offset decaying with time constant ``settle_s``, weaving across the local
    edge. Wall (log) time runs ``speedup`` times slower than simulation time.
    ``phase_bias``: added to the phase each robot publishes, as if its own pose
    estimate were off. ``hardware``: record what a hardware run has, the agents' states
    and their poses (as a localizer publishes them), with no world: no WorldInfo, Tick
    or ground truth. ``edge_wave_m``: the edge is y = edge_wave_m sin(2 pi x / 3 m) +
    edge_wave_m (recorded as WorldInfo.edge_y) instead of straight at y = 0."""
    edge_lo, edge_hi = edge
    bin_m = 0.1
    n_bins = round((edge_hi - edge_lo) / bin_m)
    depth = [1.5 if edge_lo + (b + 0.5) * bin_m < 3.0 else 0.3 for b in range(n_bins)]

    def local_edge(x: float) -> float:
        return edge_wave_m * (math.sin(TWO_PI * x / 3.0) + 1.0)

    edge_y = [local_edge(edge_lo + (b + 0.5) * bin_m) for b in range(n_bins)]
    info = WorldInfo(
        map="synthetic",
        start="offset",
        robots=robots,
        localization="truth",
        seed=0,
        duration_s=duration_s,
        dt=dt,
        edge_lo=edge_lo,
        edge_hi=edge_hi,
        bin_m=bin_m,
        patrol_depth=depth,
        robot_radius=0.17,
        min_depth=0.3,
        margin_out=0.3,
        edge_y=edge_y if edge_wave_m else [],
    )
    bounds = np.linspace(edge_lo, edge_hi, robots + 1)
    wall0 = 1_700_000_000_000_000_000
    if not hardware:
        yield "world/info", encode(info), wall0
    steps = round(duration_s / dt)
    for k in range(steps):  # as the world: ticks 0 to steps - 1, the last one done
        t = k * dt
        log_ns = wall0 + int(t / speedup * 1e9)
        poses: list[tuple[float, float, float]] = []
        for i in range(robots):
            lo, hi = float(bounds[i]), float(bounds[i + 1])
            offset = phase_offsets[i % len(phase_offsets)] * math.exp(-t / settle_s)
            phi = (TWO_PI * t / cycle_s + offset) % TWO_PI
            going_up = phi < math.pi
            frac = phi / math.pi if going_up else 2.0 - phi / math.pi
            x = lo + (hi - lo) * frac
            y = local_edge(x) - 0.3 + 0.8 * (0.5 - 0.5 * math.cos(TWO_PI * t / 2.0))
            poses.append((x, y, 0.0))
            if hardware:
                pose = Pose(t, k, i, x, y, 0.0, source="pf")
                yield f"robot/{i}/pose", encode(pose), log_ns
            state = AgentState(
                t=t,
                k=k,
                robot=i,
                lo=lo,
                hi=hi,
                phase=(phi + phase_bias[i % len(phase_bias)]) % TWO_PI,
                phase_des=phi,
                workload=0.9 * (hi - lo),
                depth_avg=0.9,
                direction=1 if going_up else -1,
                lower=i - 1,
                upper=i + 1 if i + 1 < robots else -1,
                edge_lo=edge_lo,
                edge_hi=edge_hi,
            )
            yield f"agent/{i}/state", encode(state), log_ns
        if k < garbage:
            yield "agent/0/state", b"\xc1 not msgpack", log_ns
        if hardware:
            continue
        yield "world/truth", encode(Truth.of_team(t, k, poses)), log_ns
        tick = Tick(t=t, k=k, live=list(range(robots)), done=k == steps - 1)
        yield "world/tick", encode(tick), log_ns


def write_synthetic_run(run_dir: str | Path, **kwargs: Any) -> Path:
    """Write ``run_dir``/run.mcap through the recorder's own code: the messages of
    ``synthetic_messages(**kwargs)``."""
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    writer = RunWriter(run_dir / "run.mcap", library="btrack synthetic")
    rec = Recording(writer)
    for topic, payload, log_ns in synthetic_messages(**kwargs):
        rec.handle(topic, payload, log_ns)
    writer.close()
    return run_dir / "run.mcap"
