"""Moving vehicles: boxes that drive along lanes of a route at their own speeds
(docs/simulator.md, "World effects").

A ``Traffic`` holds every vehicle of a world (lane offset from the route [m], left positive;
arc position at time 0 [m]; signed speed along the route [m/s]); ``mesh_at(t_s)`` is the
mesh of all of them at time ``t_s`` [s], which the ray caster casts beside the static world.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from pipeline.sim import meshes
from pipeline.sim.materials import Material
from pipeline.sim.route import DS_M, Route

F64 = NDArray[np.float64]

VEHICLE_SIZE_M = (4.4, 1.8, 1.5)
"""Length, width, height of a car [m]."""


def lanes_traffic(route: Route, lateral_m: F64, s_m: F64, speed_mps: F64,
                  t_s: F64) -> Traffic:
    """The traffic of vehicles at arc ``s_m`` at times ``t_s`` [s] (each its own), in lanes
    ``lateral_m`` at ``speed_mps``."""
    return Traffic(route, lateral_m, s_m - speed_mps * t_s, speed_mps)


@dataclass
class Traffic:
    """Vehicles moving along ``route``: per vehicle its lane offset [m] (left +), arc
    position at t = 0 [m], speed along the route [m/s] (negative: oncoming), and the height of
    the road under the route (``route.floor_z``)."""

    route: Route
    lateral_m: F64
    s0_m: F64
    speed_mps: F64

    def positions(self, t_s: float) -> tuple[F64, F64]:
        """((V, 3) centres [m], (V,) headings [rad]) of the vehicles on the route at ``t_s``
        (vehicles off either end of the route are dropped)."""
        s = self.s0_m + self.speed_mps * t_s
        on = (s >= 0.0) & (s <= self.route.s[-1])
        i = np.clip(np.round(s[on] / DS_M).astype(int), 0, len(self.route.xy) - 1)
        h = self.route.heading[i]
        n = np.stack([-np.sin(h), np.cos(h)], axis=-1)
        xy = self.route.xy[i] + self.lateral_m[on, None] * n
        z = self.route.floor_z[i] + VEHICLE_SIZE_M[2] / 2 + 0.25
        yaw = np.where(self.speed_mps[on] < 0, h + np.pi, h)
        return np.column_stack([xy, z]), yaw

    def mesh_at(self, t_s: float) -> tuple[F64, NDArray[np.int64]]:
        """(vertices (V, 3), triangles (T, 3)) of every vehicle at time ``t_s`` [s]."""
        mb = meshes.MeshBuilder()
        centres, yaws = self.positions(t_s)
        size = np.array([VEHICLE_SIZE_M[0], VEHICLE_SIZE_M[1], VEHICLE_SIZE_M[2] - 0.5])
        for c, yaw in zip(centres, yaws, strict=True):
            mb.add(*meshes.box(c, size, float(yaw)), Material.VEHICLE)
        return mb.build()
