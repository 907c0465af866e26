"""A clamped elastic lattice cantilever against Euler-Bernoulli beam theory.

L/h = 10, E = 10 MPa (plane strain, nu = 1/4), rho = 1000 kg/m^3, h = 2 cm
(parmps.tools.cantilever). Static tip deflections come from a direct linear
solve of the body's springs, the first frequency from the time integrator.

The lattice's bending stiffness is E2 t h^3/12 exactly for any number of nodes
through the depth from 3 (docs/elastic_lattice.md; tests/test_materials.py
checks it in pure bending), so what is left is the 2D continuum's own departure
from Euler-Bernoulli (shear deformation, under 1 % at L/h = 10) and the
lattice's discretisation of it, which shrinks under refinement.
"""

import math
import pathlib

import pytest

from parmps import config, schema
from parmps.solids.mass_spring.model import MassSpringModel
from parmps.solids.mass_spring.statics import body_static_displacement
from parmps.tools import cantilever

SLENDERNESS = 10
TOLERANCE = 0.05


@pytest.fixture(scope="module")
def reference():
    return cantilever.beam_theory(SLENDERNESS)


@pytest.fixture(scope="module")
def static_errors(reference):
    errors = {}
    for ny in (4, 6, 8):
        tip = cantilever.static_tip_deflection(ny, SLENDERNESS, tip_load=cantilever.TIP_LOAD)
        weight = cantilever.static_tip_deflection(ny, SLENDERNESS, gravity=cantilever.GRAVITY)
        errors[ny] = (tip / reference["tip_load"] - 1.0, weight / reference["gravity"] - 1.0)
    return errors


@pytest.mark.parametrize("load", [0, 1], ids=["tip_load", "gravity"])
def test_static_deflection_within_5_percent_from_4_nodes(static_errors, load):
    for ny in (4, 6, 8):
        assert abs(static_errors[ny][load]) < TOLERANCE, (ny, static_errors)


@pytest.mark.parametrize("load", [0, 1], ids=["tip_load", "gravity"])
def test_static_deflection_converges_under_refinement(static_errors, load):
    """Each refinement changes the answer less than the one before (a/h = 1/3, 1/5, 1/7)."""
    e4, e6, e8 = (static_errors[ny][load] for ny in (4, 6, 8))
    assert abs(e6 - e8) < abs(e4 - e6), static_errors


def test_first_frequency_from_the_time_integrator(reference):
    errors = {}
    for ny in (4, 6):
        omega, substeps = cantilever.first_frequency(ny, SLENDERNESS, periods=2.0)
        errors[ny] = omega / reference["omega"] - 1.0
        assert substeps > 0
    assert abs(errors[4]) < TOLERANCE, errors
    assert abs(errors[6]) < TOLERANCE, errors


def test_first_frequency_converges_under_refinement(reference):
    """The lattice's lowest eigenvalue: within 5 % from 4 nodes, each refinement changing less."""
    e4, e6, e8 = (cantilever.lattice_first_frequency(ny, SLENDERNESS) / reference["omega"] - 1.0
                  for ny in (4, 6, 8))
    assert max(abs(e4), abs(e6), abs(e8)) < TOLERANCE, (e4, e6, e8)
    assert abs(e6 - e8) < abs(e4 - e6), (e4, e6, e8)


def test_shipped_case_is_this_beam():
    """cases/elastic_cantilever.toml (6 nodes) bends statically as the 6-node beam here."""
    text = (pathlib.Path(__file__).resolve().parents[1] / "cases"
            / "elastic_cantilever.toml").read_text()
    body = MassSpringModel.from_case(schema.validate(config.load_text(text))).bodies[0]
    tip = cantilever.tip_nodes(body)
    # The load's ramp is over by t = 0.1 s.
    deflection = -body_static_displacement(body, time=0.1)[tip, 1].mean()
    expected = cantilever.static_tip_deflection(6, SLENDERNESS, tip_load=cantilever.TIP_LOAD)
    assert deflection == pytest.approx(expected, rel=1e-9)
