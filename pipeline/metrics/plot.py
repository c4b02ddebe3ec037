"""The figure of `adaptune metric rte --plot`: what evo_traj --plot and evo_ape --plot show, in
one PNG (matplotlib, Agg backend, written atomically by ``pipeline.outputs.figure``).

Three panels: a top view (x, y [m]) of the reference and of every estimate as aligned for the
APE; the APE translation error [m] of every pose along the reference's path [m]; the
translational RTE [%] of the segment of L metres starting at every frame, along the same path.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from pipeline.metrics.trajectory_error import Comparison


def plot_comparisons(reference_T: NDArray[np.float64], comparisons: Sequence[Comparison],
                     names: Sequence[str], out_png: str | Path) -> Path:
    """Write the figure (module docstring) of ``comparisons`` of the estimates ``names``
    against the reference poses ``reference_T`` (N, 4, 4)."""
    from pipeline.outputs import figure

    out_png = Path(out_png)
    with figure(out_png, 1, 3, size=(12, 3.8)) as (_, axes):
        top, ape, rte = axes[0]
        xy = reference_T[:, :2, 3]
        top.plot(xy[:, 0], xy[:, 1], "--", color="0.3", lw=1.5, label="reference")
        top.plot(*xy[0], "o", color="0.3", ms=5)
        for k, (c, name) in enumerate(zip(comparisons, names, strict=True)):
            colour = f"C{k}"
            top.plot(c.aligned[:, 0, 3], c.aligned[:, 1, 3], ".-", color=colour, lw=1.2, ms=3,
                     label=name)
            ape.plot(c.path_m, c.ape_t_m, ".-", color=colour, lw=1.2, ms=3, label=name)
            ok = np.isfinite(c.rte_t_pct)
            rte.plot(c.path_m[ok], c.rte_t_pct[ok], ".-", color=colour, lw=1.2, ms=3, label=name)
        first = comparisons[0].summary
        top.set(aspect="equal", adjustable="datalim", xlabel="x [m]", ylabel="y [m]",
                title=f"top view (estimates aligned: {first['alignment']['method']})")
        ape.set(xlabel="distance along the reference [m]", ylabel="APE translation [m]",
                title="APE along the path")
        rte.set(xlabel="segment start along the reference [m]",
                ylabel="RTE translation [%]",
                title=f"RTE over L = {first['rte']['length_m']:g} m along the path")
        for ax in (top, ape, rte):
            ax.grid(alpha=0.3)
        top.legend(fontsize=8, loc="best")
    return out_png
