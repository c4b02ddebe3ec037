"""Motion-distorted simulated scans with per-point time (issue 14, item 6), kept in the sequence
MCAP and used by the kiss_icp adapter's deskew."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import yaml
from click.testing import CliRunner

from pipeline.geometry import interpolate_rotations
from pipeline.odometry.base import Schedule
from pipeline.odometry.kiss import KissIcpAdapter
from pipeline.sequence import SequenceReader
from pipeline.sim.dataset import SimulateSection
from pipeline.sim.effects import SensorEffects
from pipeline.sim.raycast import Raycaster
from pipeline.sim.simulate import SimSpec, make_world, world_points
from stages.cli import main


def test_sweeps_carry_per_point_time_and_land_on_the_mesh_by_it(tmp_path: Path) -> None:
    """A distorted scan lands on the mesh only when each point takes the pose of its own time;
    by the stamp's pose alone it does not. Params and metadata say which mode was used."""
    out = tmp_path / "d.mcap"
    params = tmp_path / "params.yaml"  # an ideal sensor: the points land exactly on the mesh
    params.write_text(yaml.safe_dump({"simulate": {"effects": SensorEffects.ideal().model_dump()}}))
    result = CliRunner().invoke(main, ["simulate", "--params", str(params), "--world", "street",
                                       "--seed", "2", "--frames", "6", "--sensor", "vlp16",
                                       "--out", str(out)])
    assert result.exit_code == 0, result.output
    with SequenceReader(out) as r:
        scans, gt = list(r), r.ground_truth()
        assert r.info.extra["motion_distortion"].startswith("sweep: points fired over 1/10 s")
    spec = SimSpec("street", 2, 6, "vlp16", effects=SensorEffects.ideal(), motion="sweep")
    # distortion is on by default for moving sensors: the spec, the toy data set, the CLI
    assert SimSpec("street", 2, 6).motion == "sweep" == SimulateSection().motion
    w = make_world(spec)
    caster = Raycaster(w.vertices, w.triangles, spec.sensor_model())
    scan = scans[2]
    t = scan.time_s
    assert t is not None and t.shape == (len(scan.points_lidar),)
    assert 0.0 <= t.min() < 0.002 and 0.098 < t.max() < 0.1
    # per-point pose between the stamp (frame 2) and one sweep later (frame 3)
    t_keys = np.array([0.0, 0.1])
    R = interpolate_rotations(t.astype(np.float64), t_keys, gt[2:4, :3, :3])
    p = gt[2, :3, 3] + (t[:, None] / 0.1) * (gt[3, :3, 3] - gt[2, :3, 3])
    by_time = np.einsum("nij,nj->ni", R, scan.xyz.astype(np.float64)) + p
    assert np.quantile(caster.distance_to_mesh(by_time), 0.99) < 0.01
    by_stamp = caster.distance_to_mesh(world_points(scan))
    assert np.quantile(by_stamp, 0.99) > 0.1  # ~1 m of travel during the sweep
    # kiss_icp: deskew uses the times (another result); without times it changes nothing;
    # it deskews by default
    assert KissIcpAdapter().options.deskew
    schedule = Schedule.constant(KissIcpAdapter().space.defaults(), len(scans))
    runs = {d: KissIcpAdapter(deskew=d).run(scans, schedule).T_world_lidar for d in (False, True)}
    assert np.abs(runs[True] - runs[False]).max() > 1e-3
    plain = [s.__class__(s.frame, s.stamp_ns, s.points_lidar, s.T_world_lidar) for s in scans]
    np.testing.assert_array_equal(KissIcpAdapter(deskew=True).run(plain, schedule).T_world_lidar,
                                  runs[False])


def test_compensated_sweeps_land_on_the_mesh_by_the_stamp() -> None:
    """KITTI's files: swept scans moved into the frame at the stamp (no per-point time) land
    on the mesh by the stamp's pose alone, as an instantaneous scan does."""
    from pipeline.sim.simulate import scan_frame

    spec = SimSpec("street", 2, 6, "hdl64", effects=SensorEffects.ideal(), motion="compensated")
    w = make_world(spec)
    caster = Raycaster(w.vertices, w.triangles, spec.sensor_model(), w.materials)
    scan = scan_frame(caster, w, 2, 2, "compensated")
    assert scan.time_s is None
    d = caster.distance_to_mesh(world_points(scan))
    assert np.quantile(d, 0.99) < 0.01
    swept = scan_frame(caster, w, 2, 2, "sweep")
    assert np.quantile(caster.distance_to_mesh(world_points(swept)), 0.99) > 0.1
