"""A capsule in simple shear (issue 66, item 3): the pieces its measurement rests on.

The enclosed region's second moment (a closed body's shape, any d) against ellipses and
ellipsoids, the Taylor deformation and inclination read from it, and the fluid block's
initial linear velocity field. The coupled runs themselves are judged by
``python -m parmps validate capsule_shear`` (docs/validation/capsule_shear.md).
"""

import math

import numpy as np
import pytest

from conftest import case_of, ROOT
from parmps.errors import CaseError
from parmps.geometry import scene
from parmps.geometry.mesh import enclosed_moments, enclosed_volume
from parmps.geometry.shapes import icosphere
from parmps.tools import analysis


def _turned(points, angle):
    c, s = math.cos(angle), math.sin(angle)
    turn = np.eye(points.shape[1])
    turn[:2, :2] = [[c, -s], [s, c]]
    return points @ turn.T


def test_an_ellipsoids_moments_give_its_volume_centre_and_semi_axes():
    # Semi-axes 3, 2, 1 on a geodesic sphere of frequency 32 (10k triangles), turned and
    # moved: its moments' eigenvalues are V a_k^2 / 5 to the mesh's 0.05 %.
    vertices, triangles = icosphere(1.0, frequency=32)
    ellipsoid = _turned(vertices * [3.0, 2.0, 1.0], 0.4) + [5.0, -6.0, 7.0]
    volume, centre, moment = enclosed_moments(ellipsoid, triangles)
    assert volume == pytest.approx(enclosed_volume(ellipsoid, triangles), rel=1e-13)
    assert volume == pytest.approx(4.0 / 3.0 * math.pi * 6.0, rel=1e-3)
    assert np.allclose(centre, [5.0, -6.0, 7.0], atol=1e-12)
    assert np.sqrt(5.0 * np.linalg.eigvalsh(moment) / volume) == pytest.approx([1, 2, 3],
                                                                                rel=5e-4)


def test_an_ellipses_moments_in_2d():
    # A polygon of 2000 sides about the ellipse 2 x 0.5: eigenvalues A a^2 / 4.
    angle = np.linspace(0.0, 2.0 * math.pi, 2000, endpoint=False)
    loop = _turned(np.column_stack([2.0 * np.cos(angle), 0.5 * np.sin(angle)]), 0.3) + 1.0
    facets = np.column_stack([np.arange(2000), (np.arange(2000) + 1) % 2000])
    area, centre, moment = enclosed_moments(loop, facets)
    assert area == pytest.approx(math.pi, rel=1e-5)
    assert np.allclose(centre, 1.0, atol=1e-12)
    assert np.sqrt(4.0 * np.linalg.eigvalsh(moment) / area) == pytest.approx([0.5, 2.0],
                                                                                rel=1e-5)


def test_taylor_deformation_and_inclination_of_a_tilted_ellipsoid():
    vertices, triangles = icosphere(1.0, frequency=24)
    moments = []
    for angle in (0.0, 0.25 * math.pi, 0.6):
        shape = _turned(vertices * [1.5, 1.0, 0.8], angle)
        moments.append(enclosed_moments(shape, triangles)[2])
    deformation, inclination = analysis.taylor_deformation(np.array(moments), [0, 1])
    assert deformation == pytest.approx([0.2] * 3, rel=1e-3)      # (1.5 - 1)/(1.5 + 1)
    assert inclination == pytest.approx([0.0, 0.25 * math.pi, 0.6], abs=1e-6)


def test_a_fluid_block_starts_in_the_linear_flow_it_is_given():
    case = case_of(ROOT / "tests" / "cases" / "periodic_couette.toml",
                   "fluid_block.0.velocity=[0.001, 0.0]",
                   "fluid_block.0.velocity_gradient=[[0.0, 0.5], [0.0, 0.0]]")
    block = case["fluid_block"][0]
    position, _, velocity = scene.fluid_block(block, case["particles"]["spacing"], "block")
    assert np.allclose(velocity[:, 0], 0.001 + 0.5 * position[:, 1], atol=1e-15)
    assert np.all(velocity[:, 1] == 0.0)


def test_a_velocity_gradient_of_the_wrong_size_is_refused():
    with pytest.raises(CaseError, match=r"fluid_block\[0\]\.velocity_gradient has 1 rows"):
        case_of(ROOT / "tests" / "cases" / "periodic_couette.toml",
                "fluid_block.0.velocity_gradient=[[0.0, 0.5]]")
