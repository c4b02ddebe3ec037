"""Surface materials of the simulated worlds and their reflectance at the LiDAR's wavelength.

Every triangle of a world carries a material (``Material``, stored as uint8). The sensor model
reads its diffuse reflectance at 905 nm (``REFLECTANCE``: how strong the echo is, hence whether
a return comes back, and the intensity) and whether it is foliage (``VEGETATION``: the beam
enters the volume; docs/simulator.md, "Sensor effects").

Reflectances are typical values of the ECOSTRESS spectral library (Meerdink et al., Remote
Sensing of Environment 230, 2019) near 905 nm: asphalt 0.08-0.17, concrete and plaster
0.3-0.45, green grass and leaves 0.45-0.55, dry soil 0.25-0.35, bark 0.3-0.4, painted metal
from 0.05 (black) to 0.7 (white).
"""

from __future__ import annotations

from enum import IntEnum

import numpy as np
from numpy.typing import NDArray


class Material(IntEnum):
    """What a triangle is made of."""

    GROUND = 0
    """Soil and grass beside the road, cave floors and open terrain."""
    ROAD = 1
    """Asphalt."""
    BUILDING = 2
    """Plaster, concrete, brick."""
    VEGETATION = 3
    """Tree crowns, hedges, bushes: a volume the beam enters."""
    VEHICLE = 4
    """Painted metal and glass of cars."""
    METAL = 5
    """Poles, guard rails, signs (galvanised or painted steel)."""
    ROCK = 6
    """Rock walls and boulders."""
    WOOD = 7
    """Tree trunks."""


REFLECTANCE = {
    Material.GROUND: 0.35,
    Material.ROAD: 0.12,
    Material.BUILDING: 0.35,
    Material.VEGETATION: 0.5,
    Material.VEHICLE: 0.3,
    Material.METAL: 0.4,
    Material.ROCK: 0.3,
    Material.WOOD: 0.35,
}
"""Diffuse reflectance at 905 nm of every material (module docstring)."""


def reflectance_table() -> NDArray[np.float32]:
    """(len(Material),) reflectance indexed by material id."""
    return np.array([REFLECTANCE[m] for m in Material], np.float32)


RELIEF = {
    Material.GROUND: 1.0,
    Material.ROAD: 0.03,
    Material.BUILDING: 1.0,
    Material.VEGETATION: 0.0,
    Material.VEHICLE: 1.0,
    Material.METAL: 0.2,
    Material.ROCK: 1.5,
    Material.WOOD: 0.5,
}
"""Relative relief of every material (SensorEffects.surface_relief_m scales it): facades,
cars, soil and rock are rough at the decimetre scale the meshes leave out, asphalt and metal
are smooth, foliage has its own model (the volume)."""


def relief_table() -> NDArray[np.float32]:
    """(len(Material),) relative relief indexed by material id."""
    return np.array([RELIEF[m] for m in Material], np.float32)
