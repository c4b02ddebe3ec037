"""The one mapping of parameters to the unit cube (pipeline/unit_cube.py)."""

from __future__ import annotations

import math

import numpy as np

from pipeline.odometry.base import ParameterSpace, ParamSpec
from pipeline.unit_cube import UnitCube

SPACE = ParameterSpace((
    ParamSpec("resolution", 1.0, 10.0, 4.0),
    ParamSpec("voxel", 0.1, 10.0, 1.0, log=True),
    ParamSpec("iterations", 2.0, 9.0, 4.0, kind="int"),
))


def test_bounds_map_to_the_cube_and_back() -> None:
    cube = SPACE.unit_cube
    X = np.array([[1.0, 0.1, 2.0], [10.0, 10.0, 9.0], [5.5, 1.0, 5.0]])
    U = cube.to_unit(X)
    np.testing.assert_allclose(U[:2], [[0, 0, 0], [1, 1, 1]], atol=1e-15)
    np.testing.assert_allclose(U[2], [0.5, 0.5, 3 / 7], rtol=1e-12)  # log: the geometric middle
    np.testing.assert_allclose(cube.from_unit(U), X, rtol=1e-12)


def test_from_unit_clips_and_rounds_half_to_even() -> None:
    cube = SPACE.unit_cube
    out = cube.from_unit(np.array([[-0.5, 2.0, 0.5 / 7], [0.5, 0.5, 1.5 / 7]]))
    assert out[0].tolist() == [1.0, 10.0, 2.0]  # 2.5 rounds to 2
    assert out[1, 2] == 4.0 and math.isclose(out[1, 1], 1.0)  # 3.5 rounds to 4
    snapped = cube.snap(np.array([[0.3, 0.3, 0.3]]))
    assert cube.from_unit(snapped)[0, 2] == round(2 + 0.3 * 7)


def test_parameter_space_and_manifest_json_share_it() -> None:
    params = {"resolution": 2.0, "voxel": 0.5, "iterations": 7.0}
    u = SPACE.to_unit(params)
    from_json = UnitCube.of(SPACE.to_json())
    assert from_json == SPACE.unit_cube
    np.testing.assert_array_equal(u, from_json.to_unit(from_json.values(params))[0])
    back = SPACE.from_unit(u)
    assert back.keys() == params.keys()
    np.testing.assert_allclose(list(back.values()), list(params.values()), rtol=1e-12)
