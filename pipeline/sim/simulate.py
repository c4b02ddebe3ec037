"""Simulate a sequence: build a world, drive the sensor through it, write the sequence MCAP."""

from __future__ import annotations

import logging
import os
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Literal

import numpy as np
from numpy.typing import NDArray

from pipeline.errors import ConfigError
from pipeline.geometry import inv_se3
from pipeline.io_utils import STDOUT, check_plain_name, refuse_input_as_output
from pipeline.sequence import Compression, EnvLabel, Scan, SequenceInfo, SequenceWriter
from pipeline.sim.effects import SensorEffects
from pipeline.sim.kitti_world import KittiWorldEffects, check_kitti_args
from pipeline.sim.sensors import SENSOR_TITLES, SensorModel, get_sensor
from pipeline.sim.worlds import DEFAULT_SEGMENTS, WORLDS, World, build_world, check_world_args

if TYPE_CHECKING:  # the caster (numba, open3d) loads on first use: params loading stays light
    from pipeline.sim.raycast import Raycaster

log = logging.getLogger(__name__)


MotionMode = Literal["none", "sweep", "compensated"]
"""How a scan relates to the sensor's motion: ``none`` instantaneous scans; ``sweep`` every
scan swept over 1 / rate_hz s from its stamp, points measured from the moving sensor, with
per-point time (Raycaster.sweep); ``compensated`` the sweep moved into the frame at its stamp,
without times (KITTI's odometry files)."""


@dataclass(frozen=True)
class SimSpec:
    """What to simulate: a world (``WORLDS``, or ``kitti``: the simulated-KITTI world of the
    ground-truth file ``kitti_trajectory`` NN.txt, frames ``start`` .. ``start + frames - 1``),
    its seed, frame count, sensor and sensor effects, and how scans follow the motion."""

    world: str
    seed: int
    frames: int
    sensor: str = "hdl32"
    segments: tuple[str, ...] = DEFAULT_SEGMENTS
    effects: SensorEffects = field(default_factory=lambda: SensorEffects.model_validate({}))
    motion: MotionMode = "sweep"
    kitti_trajectory: Path | None = None
    start: int = 0
    kitti_world: KittiWorldEffects = field(
        default_factory=lambda: KittiWorldEffects.model_validate({}))

    def sensor_model(self) -> SensorModel:
        return get_sensor(self.sensor, self.effects)

    def rays(self) -> int:
        """Rays fired over the whole world (frames x beams x azimuths): what simulating it,
        and running odometry on its points, costs in proportion."""
        sensor = self.sensor_model()
        return self.frames * sensor.beams * sensor.azimuths

    def check(self) -> None:
        """ConfigError for an unknown world / sensor / segment, a bad frame count or seed."""
        if not 0 <= self.seed < 2**63:
            raise ConfigError(f"seed must be an integer in [0, 2^63), got {self.seed}")
        self.sensor_model()
        if self.world == "kitti":
            check_kitti_args(self.kitti_trajectory, self.start, self.frames)
        else:
            check_world_args(self.world, self.frames, self.segments)
            if self.kitti_trajectory is not None:
                raise ConfigError(f"--kitti-trajectory needs --world kitti, got --world "
                                  f"{self.world}")


@dataclass(frozen=True)
class SimSummary:
    """What ``simulate_sequence`` wrote."""

    path: Path
    name: str
    frames: int
    points: int
    length_m: float
    labels: list[EnvLabel]


def derive_seed(base_seed: int, name: str) -> int:
    """A stable per-sequence seed from the shared base seed and the sequence name."""
    return int(np.random.SeedSequence([base_seed, zlib.crc32(name.encode())]).generate_state(1)[0])


def label_ranges(frame_labels: list[str]) -> list[EnvLabel]:
    """Run-length ranges (inclusive) of per-frame labels."""
    out: list[EnvLabel] = []
    for i, lab in enumerate(frame_labels):
        if out and out[-1].label == lab and out[-1].end == i - 1:
            out[-1] = EnvLabel(out[-1].start, i, lab)
        else:
            out.append(EnvLabel(i, i, lab))
    return out


def make_world(spec: SimSpec) -> World:
    """The world and drive of ``spec`` (mesh built once)."""
    spec.check()
    if spec.world == "kitti":
        from pipeline.sim.kitti_world import build_kitti_world

        assert spec.kitti_trajectory is not None
        path = Path(spec.kitti_trajectory)
        return build_kitti_world(path, path.stem, spec.seed, spec.start,
                                 spec.start + spec.frames - 1, spec.kitti_world)
    return build_world(spec.world, spec.seed, spec.frames, spec.sensor_model().rate_hz,
                       tuple(spec.segments))


def iter_scans(
    world: World, sensor: SensorModel, seed: int, frames: range | None = None,
    motion: MotionMode = "none",
) -> Iterator[Scan]:
    """Ray-cast scans of ``world`` (``scan_frame`` for each of ``frames``, default all)."""
    from pipeline.sim.raycast import Raycaster

    caster = Raycaster(world.vertices, world.triangles, sensor, world.materials, world.seed)
    for k in frames if frames is not None else range(world.frames):
        yield scan_frame(caster, world, seed, k, motion)


def scan_frame(caster: Raycaster, world: World, seed: int, k: int,
               motion: MotionMode = "none") -> Scan:
    """Frame k of ``world`` cast by ``caster``: its noise comes from the seed (seed, 1, k)
    alone, so any frame can be reproduced without the ones before it. A sweep (``motion``)
    runs from pose k to pose k + 1 (the last one continues the motion before it); the ground
    truth is the pose at the stamp, the sweep's start. The world's traffic is where it is at
    the stamp (instantaneous) or half a sweep later."""
    T_all = world.poses.T_world_lidar
    T = T_all[k]
    stamp_ns = int(world.poses.stamps_ns[k])
    rng = np.random.default_rng([seed, 1, k])
    when_s = stamp_ns * 1e-9 + (0.0 if motion == "none" else 0.5 / caster.sensor.rate_hz)
    movers = world.traffic.mesh_at(when_s) if world.traffic is not None else None
    if motion == "none":
        return Scan(k, stamp_ns, caster.scan(T, rng, movers), T)
    T_end = T_all[k + 1] if k + 1 < len(T_all) else T @ inv_se3(T_all[k - 1]) @ T
    pts, time_s = caster.sweep(T, T_end, rng, movers, compensate=motion == "compensated")
    return Scan(k, stamp_ns, pts, T, None if motion == "compensated" else time_s)


@dataclass(frozen=True)
class SimulatedScans:
    """A simulated sequence held in memory: the scans (``Scan``: (N, 4) float32 points in the
    lidar frame, the ground-truth pose, per-point times where swept) and each frame's
    environment label. What ``simulate_sequence`` writes and ``SequenceReader`` gives back."""

    scans: list[Scan]
    labels: list[str]


def simulate_scans(spec: SimSpec) -> SimulatedScans:
    """Simulate ``spec`` into memory, for a world that is run and thrown away (the verdict's
    suites): the same scans as ``simulate_sequence`` writes, without encoding, compressing and
    decoding them (x0.71 of a suite's wall time: docs/performance.md, "The verdict's suites")."""
    world = make_world(spec)
    scans = list(iter_scans(world, spec.sensor_model(), spec.seed, motion=spec.motion))
    return SimulatedScans(scans, list(world.poses.frame_labels))


def simulate_sequence(
    spec: SimSpec, out_path: str | Path, name: str | None = None, progress: bool = False,
    compression: Compression = "zstd",
) -> SimSummary:
    """Simulate ``spec`` and write the sequence MCAP at ``out_path`` (atomically), its chunks
    compressed by ``compression``."""
    refuse_input_as_output(out_path, [spec.kitti_trajectory])
    default = spec.world if os.fspath(out_path) == STDOUT else Path(out_path).stem  # --out -
    name = check_plain_name(name or default, "the sequence name")  # before the work
    world = make_world(spec)
    source = "simulation:" + (f"kitti {Path(spec.kitti_trajectory).name}"
                              if spec.kitti_trajectory else spec.world)
    return write_world(world, spec.sensor_model(), spec.seed, out_path,
                       name, source, _extra(spec, world), progress, spec.motion, compression)


def write_world(world: World, sensor: SensorModel, seed: int, out_path: str | Path, name: str,
                source: str, extra: dict[str, str], progress: bool = False,
                motion: MotionMode = "none", compression: Compression = "zstd") -> SimSummary:
    """Ray-cast every frame of ``world`` (noise from ``seed``, sweeps by ``motion``, as
    ``iter_scans``) into the sequence MCAP ``out_path`` (atomically, chunks compressed by
    ``compression``), labels per frame range from the world's poses. ``progress``: a bar on a
    terminal, log lines elsewhere (``pipeline.progress``)."""
    from pipeline.progress import progress as shown

    labels = label_ranges(world.poses.frame_labels)
    info = SequenceInfo(name=name, sensor=SENSOR_TITLES[sensor.name], source=source,
                        labels=labels, extra=extra)
    points = 0
    with SequenceWriter(out_path, info, compression=compression) as w:
        scans = iter_scans(world, sensor, seed, motion=motion)
        for scan in shown(scans, world.frames, f"simulate {name}", "scan", enabled=progress):
            w.add(scan.stamp_ns, scan.points_lidar, scan.T_world_lidar, scan.time_s)
            points += len(scan.points_lidar)
    length = float(
        np.linalg.norm(np.diff(world.poses.T_world_lidar[:, :3, 3], axis=0), axis=1).sum()
    )
    log.debug("%s: %d frames, %.0f m, %d points", name, world.frames, length, points)
    return SimSummary(Path(out_path), name, world.frames, points, length, labels)


def sensor_extra(sensor: SensorModel, motion: MotionMode) -> dict[str, str]:
    """The metadata of a simulated sequence that says how it was scanned."""
    return {
        "sensor_model": sensor.name,
        "effects": sensor.effects.model_dump_json(),
        "range_noise_m": str(sensor.range_noise_m),
        "dropout": str(sensor.dropout),
        "motion": motion,
        "motion_distortion": {
            "none": "none (instantaneous scans)",
            "sweep": f"sweep: points fired over 1/{sensor.rate_hz:g} s from the stamp, "
                     "per-point time [s] in the PointCloud2 field 'time'",
            "compensated": f"compensated: swept over 1/{sensor.rate_hz:g} s, moved into the "
                           "frame at the stamp (no per-point time)"}[motion],
    }


def _extra(spec: SimSpec, world: World) -> dict[str, str]:
    extra = {"world": spec.world, "seed": str(spec.seed), "segments": ",".join(spec.segments),
             "mesh_triangles": str(len(world.triangles))}
    if spec.kitti_trajectory is not None:
        extra |= {"kitti_sequence": Path(spec.kitti_trajectory).stem,
                  "first_frame": str(spec.start),
                  "last_frame": str(spec.start + spec.frames - 1)}
    return extra | sensor_extra(spec.sensor_model(), spec.motion)


def spec_of(info: SequenceInfo) -> SimSpec | None:
    """The SimSpec a simulated sequence was made from (its metadata), or None for other data
    and simulated KITTI (whose pose files are not recorded)."""
    extra = info.extra
    if not info.source.startswith("simulation:") or extra.get("world") not in WORLDS:
        return None
    segments = tuple(s for s in extra.get("segments", "").split(",") if s) or DEFAULT_SEGMENTS
    effects = (SensorEffects.model_validate_json(extra["effects"]) if "effects" in extra
               else SensorEffects.model_validate({"range_noise_m": float(extra["range_noise_m"]),
                                                  "dropout": float(extra["dropout"])}))
    motion = extra.get("motion") or (
        "sweep" if extra.get("motion_distortion", "none").startswith("sweep") else "none")
    return SimSpec(extra["world"], int(extra["seed"]), info.frame_count,
                   extra.get("sensor_model", "hdl32"), segments, effects,
                   motion)  # type: ignore[arg-type]


def world_points(scan: Scan) -> NDArray[np.float64]:
    """(N, 3) points of ``scan`` in the world frame (by its ground-truth pose)."""
    assert scan.T_world_lidar is not None
    T = scan.T_world_lidar
    return scan.xyz.astype(np.float64) @ T[:3, :3].T + T[:3, 3]
