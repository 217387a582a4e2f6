"""``btrack view``: a running team (simulated or real) served to Foxglove over its
WebSocket protocol, the same channels as a converted recording (``scene.build``).

Bounded, so that a slow viewer never slows the lockstep: the view is a client of the
team's router (the recorder's, in ``btrack sim``), so the lockstep's processes send it
nothing of their own; it takes the bus through a ring that drops the oldest when full
(a Zenoh FIFO would hold up the router's thread); it keeps only the newest message of
each topic and draws a frame ``--rate`` times a wall second, however fast the run
goes; and the Foxglove SDK's server keeps a bounded queue per viewer.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from collections import deque
from pathlib import Path
from typing import Any

import zenoh

from recorder import topics
from scene import build
from wire.codec import DecodeError, decode
from wire.keys import Keys
from wire.messages import MAX_SCANNERS, AgentState, Particles, Pose, Scan, Sense, Truth, WorldInfo
from wire.session import SessionOptions, add_session_args, bounded_session, options_from_args

RING = 4096  # samples held between frames; older ones are dropped
STATIC_EVERY_S = 1.0  # the map and the bodies again, for a viewer that joined late


class LiveView:
    """The pure part: raw payloads in (the newest of each topic kept, undecoded), one
    frame of Foxglove messages out, each built from the newest messages."""

    def __init__(self) -> None:
        self.latest: dict[str, bytes] = {}
        self.scans: deque[bytes] = deque(maxlen=MAX_SCANNERS)
        self.info: WorldInfo | None = None
        self.shape: build.EdgeShape | None = None
        self.drawn_k: dict[str, int] = {}  # the tick of each topic last drawn
        self.bodies: set[int] = set()
        self.static_ns = 0  # when the map and bodies were last sent
        self.dropped = 0

    def take(self, topic: str, payload: bytes) -> None:
        if topic == "laser/scan":
            self.scans.append(payload)
        elif not topic.startswith(("alive/", "invalid/")):
            self.latest[topic] = payload

    def _decode(self, cls: type, payload: bytes) -> Any:
        try:
            return decode(cls, payload)
        except DecodeError:
            self.dropped += 1
            return None

    def _fresh(self, topic: str, k: int) -> bool:
        """Not drawn yet (a message of a later tick than the last drawn on ``topic``)."""
        if self.drawn_k.get(topic, -1) >= k:
            return False
        self.drawn_k[topic] = k
        return True

    def frame(self, stamp_ns: int) -> list[tuple[str, Any]]:
        """The Foxglove messages of what came since the last frame."""
        out: list[tuple[str, Any]] = []
        info_raw = self.latest.pop("world/info", None)
        if info_raw is not None:
            info = self._decode(WorldInfo, info_raw)
            if info is not None and info != self.info:
                self.info = info
                self.shape = build.EdgeShape.of(info) if info.patrol_depth else None
                self.static_ns = 0
        scans: dict[int, Scan] = {}
        for payload in self.scans:
            scan = self._decode(Scan, payload)
            if scan is not None and (scan.scanner not in scans
                                     or scans[scan.scanner].k < scan.k):
                scans[scan.scanner] = scan
        self.scans.clear()
        for scanner, scan in sorted(scans.items()):
            if self._fresh(build.scan_topic(scanner), scan.k):
                out.append((build.scan_topic(scanner), build.laser_scan(scan, stamp_ns)))
        true_poses: dict[int, build.Pose2] = {}
        truth_raw = self.latest.get("world/truth")
        if truth_raw is not None:
            truth = self._decode(Truth, truth_raw)
            if truth is not None and self._fresh(build.POSES_TRUE_TOPIC, truth.k):
                true_poses = build.truth_poses(truth)
                out.append((build.TF_TOPIC, build.frame_transforms(true_poses, stamp_ns)))
                out.append((build.POSES_TRUE_TOPIC, build.poses_in_frame(true_poses,
                                                                         stamp_ns)))
        estimated: dict[int, build.Pose2] = {}
        states: dict[int, AgentState] = {}
        newest = -1
        for topic, payload in self.latest.items():
            cls = topics.message_type(topic)
            if cls is Pose:
                pose = self._decode(Pose, payload)
                if pose is not None:
                    estimated[pose.robot] = (pose.x, pose.y, pose.theta)
            elif cls is Sense and b"pose" in payload:
                sense = self._decode(Sense, payload)
                if sense is not None and sense.pose:
                    x, y, th = sense.pose
                    estimated[sense.robot] = (x, y, th)
            elif cls is AgentState:
                state = self._decode(AgentState, payload)
                if state is not None:
                    states[state.robot] = state
                    newest = max(newest, state.k)
            elif cls is Particles:
                cloud = self._decode(Particles, payload)
                if cloud is not None and self._fresh(build.particles_topic(cloud.robot), cloud.k):
                    out.append((build.particles_topic(cloud.robot),
                                build.particle_cloud(cloud, stamp_ns)))
        if estimated:
            out.append((build.POSES_ESTIMATED_TOPIC, build.poses_in_frame(estimated,
                                                                          stamp_ns)))
            if truth_raw is None:  # no truth (hardware): the frames follow the estimates
                out.append((build.TF_TOPIC, build.frame_transforms(estimated, stamp_ns)))
        if states and self._fresh(build.SEGMENTS_SCENE_TOPIC, newest):
            t = max(s.t for s in states.values())
            out.append((build.SEGMENTS_SCENE_TOPIC,
                        build.segments_scene(self.shape, states, t, newest, stamp_ns)))
            out.append((build.ERRORS_TOPIC, build.errors(states, t, newest)))
            robots = build.team_size(set(states) | set(estimated) | set(true_poses), self.info)
            out.append((build.SEGMENTS_TOPIC, build.segments(states, robots, t, newest)))
        drawn = set(true_poses) | set(estimated)
        again = stamp_ns - self.static_ns >= STATIC_EVERY_S * 1e9
        if not self.bodies.issuperset(drawn) or (again and self.bodies):
            self.bodies |= drawn
            out.append((build.ROBOTS_TOPIC, build.robots_scene(
                self.bodies, self.info.robot_radius if self.info else 0.17, stamp_ns)))
        if again and self.info is not None and self.info.patrol_depth:
            out.append((build.MAP_TOPIC, build.map_scene(self.info, stamp_ns)))
        if again:
            self.static_ns = stamp_ns
        return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="btrack view",
        description="Serve a running team to Foxglove over its WebSocket protocol (connect "
        "Foxglove to ws://HOST:PORT): the scene, the scans, the poses and the errors.")
    p.add_argument("--run", type=Path, metavar="DIR",
                   help="join the run of DIR/bus.json (btrack sim writes it) as a client of "
                   "its router; else give --ns and --connect")
    p.add_argument("--port", type=int, default=8765, help="WebSocket port (8765)")
    p.add_argument("--host", default="127.0.0.1", help="address to serve on (127.0.0.1)")
    p.add_argument("--rate", type=float, default=10.0, metavar="HZ",
                   help="frames per wall second sent, whatever the run's speed (10)")
    add_session_args(p)
    return p


def _options(args: argparse.Namespace) -> SessionOptions:
    if args.run is None:
        return options_from_args(args)
    bus = json.loads((args.run / "bus.json").read_text())
    return SessionOptions(ns=bus["ns"], mode="client", connect=(bus["connect"],),
                          multicast=False)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        opts = _options(args)
        keys = Keys(opts.ns)
    except (OSError, ValueError, KeyError) as exc:
        print(f"btrack view: {exc}", file=sys.stderr)
        return 2
    if not 0 <= args.port <= 65535 or not args.rate > 0:
        print("btrack view: --port must be in 0..65535 and --rate positive", file=sys.stderr)
        return 2
    import foxglove

    from scene.convert import PLOT_SCHEMAS, descriptor_set

    context = foxglove.Context()
    try:
        server = foxglove.start_server(name="btrack", host=args.host, port=args.port,
                                       context=context)
    except Exception as exc:  # a port in use, an address not ours
        print(f"btrack view: cannot serve on {args.host}:{args.port}: {exc}", file=sys.stderr)
        return 1
    print(f"btrack view: serving {keys.ns} on ws://{args.host}:{server.port}", file=sys.stderr,
          flush=True)
    stopping = False

    def stop(*_: Any) -> None:
        nonlocal stopping
        stopping = True

    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, stop)
    channels: dict[str, foxglove.Channel] = {}
    view = LiveView()
    frames = sent = 0
    try:
        with bounded_session(opts, "btrack view") as session:
            sub = session.declare_subscriber(keys.everything(), zenoh.handlers.RingChannel(RING))
            period = 1.0 / args.rate
            next_at = time.monotonic()
            while not stopping:
                while (sample := sub.try_recv()) is not None:
                    view.take(keys.relative(str(sample.key_expr)), sample.payload.to_bytes())
                for topic, msg in view.frame(time.time_ns()):
                    channel = channels.get(topic)
                    if channel is None:
                        if isinstance(msg, dict):
                            channel = foxglove.Channel(topic, schema=PLOT_SCHEMAS[topic],
                                                       context=context)
                        else:
                            schema = foxglove.Schema(name=msg.DESCRIPTOR.full_name,
                                                     encoding="protobuf",
                                                     data=descriptor_set(type(msg)))
                            channel = foxglove.Channel(topic, schema=schema,
                                                       message_encoding="protobuf",
                                                       context=context)
                        channels[topic] = channel
                    channel.log(msg if isinstance(msg, dict) else msg.SerializeToString())
                    sent += 1
                frames += 1
                next_at += period
                time.sleep(max(0.0, next_at - time.monotonic()))
            sub.undeclare()
    finally:
        server.stop()
    print(json.dumps({"view": True, "frames": frames, "messages": sent,
                      "dropped": view.dropped}), flush=True)
    return 0
