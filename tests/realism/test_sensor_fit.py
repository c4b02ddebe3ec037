"""KITTI's HDL-64E as its scans show it (docs/simulator.md, "Sensor model"): the table in
pipeline/sim/kitti_sensor.py is what studies/realism/sensor_fit.py derives from the kitti_mini
scans."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.sim import kitti_sensor
from studies.realism.sensor_fit import fit_sensor


def test_the_stored_kitti_hdl64_is_what_the_scans_show(kitti_root: Path) -> None:
    scans = [np.fromfile(kitti_root / "sequences" / s / "velodyne" / f"{f:06d}.bin",
                         np.float32).reshape(-1, 4) for s in ("01", "04", "06", "10")
             for f in range(10)]
    fit = fit_sensor(scans)
    np.testing.assert_allclose(fit.elevations_deg, kitti_sensor.ELEVATIONS_DEG, atol=2e-3)
    np.testing.assert_allclose(fit.heights_m, kitti_sensor.HEIGHTS_M, atol=2e-3)
    hidden: dict[int, list[tuple[float, float]]] = {}
    for ring, a, b in fit.hidden:
        hidden.setdefault(ring, []).append((a, b))
    assert {k: tuple(v) for k, v in hidden.items()} == {
        k: tuple((float(a), float(b)) for a, b in v)
        for k, v in kitti_sensor.HIDDEN_SECTORS_DEG.items()}
