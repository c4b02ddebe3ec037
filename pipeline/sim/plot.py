"""Top-down picture of a simulated world, its trajectory and one scan (matplotlib, Agg)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.io_utils import atomic_path
from pipeline.sim.simulate import SimSpec, iter_scans, make_world, world_points

LABEL_COLOURS = {"cave": "tab:brown", "open": "tab:green", "street": "tab:blue",
                 "urban": "tab:red", "residential": "tab:cyan", "rural": "tab:olive",
                 "highway": "tab:orange"}
"""The colour of every environment label (toy worlds and simulated KITTI) in every figure."""


def plot_world(
    spec: SimSpec, out_png: str | Path, scan_frame: int | None = None, cell_m: float = 0.5
) -> Path:
    """Write a top-down PNG of ``spec``'s world: mesh (height map seen from above, grey),
    trajectory coloured by environment label, and the scan of ``scan_frame`` (default: middle)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    world = make_world(spec)
    k = world.frames // 2 if scan_frame is None else min(max(scan_frame, 0), world.frames - 1)
    scan = next(iter_scans(world, spec.sensor_model(), spec.seed, range(k, k + 1), spec.motion))
    height, extent = height_map(world.vertices, world.triangles, cell_m)
    fig, ax = plt.subplots(figsize=(10, 10), dpi=110)
    ax.imshow(height.T, origin="lower", extent=extent, cmap="gray", interpolation="nearest")
    xyz = world.poses.T_world_lidar[:, :3, 3]
    labels = np.array(world.poses.frame_labels)
    for lab, colour in LABEL_COLOURS.items():
        sel = labels == lab
        if sel.any():
            ax.plot(xyz[sel, 0], xyz[sel, 1], ".", ms=2, color=colour, label=f"trajectory ({lab})")
    pts = world_points(scan)
    ax.scatter(pts[:, 0], pts[:, 1], s=0.2, c="tab:red", linewidths=0, label=f"scan of frame {k}")
    ax.plot(*xyz[k, :2], "k*", ms=12)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"{spec.world} world, seed {spec.seed}, {world.frames} frames, {spec.sensor}")
    ax.legend(loc="best", markerscale=5, fontsize=8)
    with atomic_path(out_png) as tmp:
        fig.savefig(tmp, format="png", bbox_inches="tight")
    plt.close(fig)
    return Path(out_png)


def height_map(
    vertices: np.ndarray, triangles: np.ndarray, cell_m: float, max_cells: int = 4_000_000
) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """Top surface of the mesh seen from above: (nx, ny) heights [m] (NaN where empty) and
    the imshow extent (x0, x1, y0, y1). Cast by vertical rays, one per cell."""
    import open3d as o3d

    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    cell_m = max(cell_m, float(np.sqrt((hi[0] - lo[0]) * (hi[1] - lo[1]) / max_cells)))
    xs = np.arange(lo[0], hi[0], cell_m) + cell_m / 2
    ys = np.arange(lo[1], hi[1], cell_m) + cell_m / 2
    X, Y = np.meshgrid(xs, ys, indexing="ij")
    origin = np.array([lo[0], lo[1], 0.0])
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(
        o3d.core.Tensor((vertices - origin).astype(np.float32)),  # type: ignore[call-overload]
        o3d.core.Tensor(triangles.astype(np.uint32)),  # type: ignore[call-overload]
    )
    rays = np.zeros((X.size, 6), np.float32)
    rays[:, 0], rays[:, 1], rays[:, 2] = (X - lo[0]).ravel(), (Y - lo[1]).ravel(), hi[2] + 1.0
    rays[:, 5] = -1.0
    t = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()  # type: ignore[call-overload]
    z = np.where(np.isfinite(t), hi[2] + 1.0 - t, np.nan).reshape(X.shape)
    return z, (
        float(xs[0] - cell_m / 2),
        float(xs[-1] + cell_m / 2),
        float(ys[0] - cell_m / 2),
        float(ys[-1] + cell_m / 2),
    )
