"""Sim-to-real comparison (issue 30; docs/design.md, "The sim-to-real comparison").

Rows: per real KITTI slice (../shared/data/kitti_mini: 01, 04, 06, 10, frames 0-9) and
algorithm (gicp, kiss_icp at their defaults), simulated / real of the median frame-to-frame
error (translation and rotation), then of the 90th percentiles pooled over the slices, the
count within the target and the count of per-slice misses beyond the real median's own
interval (``RealismResult.beyond_real_noise``). The
simulated side: simulated KITTI (params.yaml ``simulate_kitti``) along the same ground-truth
poses, ADAPTUNE_BENCH_REALISM_REPLICAS worlds a slice (default 3). The table and the figure
are written to ADAPTUNE_BENCH_REALISM_OUT (default /tmp/adaptune_realism). A smoke run
compares frames 0-2 of 04 with one world, into a temporary folder.
"""

from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

from common import Row, data_root, size, smoke


def run() -> list[Row]:
    from pipeline.config import load_section
    from pipeline.sim.kitti_dataset import SimulateKittiSection
    from studies.realism.compare import SLICES, TARGET_RATIO, run_realism
    from studies.realism.report import write_realism

    root = data_root()
    params = Path(__file__).resolve().parents[1] / "params.yaml"
    section = load_section(params, "simulate_kitti", SimulateKittiSection)
    replicas = size(int(os.environ.get("ADAPTUNE_BENCH_REALISM_REPLICAS", "3")), 1)
    slices = size(SLICES, (("04", 0, 2),))
    result = run_realism(root / "kitti_mini" / "dataset", root / "kitti_trajectories", section,
                         replicas, slices)
    with (tempfile.TemporaryDirectory(prefix="adaptune_realism_") if smoke()
          else contextlib.nullcontext(os.environ.get("ADAPTUNE_BENCH_REALISM_OUT",
                                                     "/tmp/adaptune_realism"))) as out_dir:
        out = write_realism(result, out_dir)
    within, beyond = result.within_target(), result.beyond_real_noise()
    return [*(Row(f"realism {name}: simulated / real", ratio, "x", f"table {out[1]}",
                  f"{1 / TARGET_RATIO:.2f} .. {TARGET_RATIO:g}")
              for name, ratio in result.ratios().items()),
            Row("realism figures within the target", sum(within.values()), "of "
                f"{len(within)}", "", f"all {len(within)}"),
            Row("realism per-slice misses beyond the real median's own interval",
                sum(beyond.values()), f"of {len(beyond)}",
                "the rest may be the real slices' few steps (realism.md)", "0")]
