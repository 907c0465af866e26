"""The fluid's viscous drag on a body's nodes, taken backward Euler in every substep
(parmps.solids.mass_spring.kernels.drag_kick; the coupling's split of the node force,
parmps.coupling.weak.WeakCoupling.node_forces).

Checked: the kick without a drag is the plain kick bit for bit; the steady slip under a
constant force is a / rate exactly at any h rate; the volume constraint (a lattice body,
compiled and numpy substeps) and the area and volume constraints (a membrane) hold to their
tolerances with a drag of h rate/2 = 5, where they would not if the multipliers predicted the
next position without it; the fluid force a body reports is the held force plus the step's
mean drag.
"""

import numpy as np
import pytest

from parmps.solids.mass_spring.kernels import drag_kick
from test_membrane import PULL, _case
from test_solid_3d import body_3d


def test_without_a_drag_the_kick_is_the_plain_kick_and_the_steady_slip_is_exact():
    rng = np.random.default_rng(3)
    velocity, acceleration = rng.standard_normal((2, 5, 3))
    plain = velocity + 0.25 * acceleration
    kicked = velocity.copy()
    drag_kick(kicked, acceleration, np.zeros(5), rng.standard_normal((5, 3)), 0.25)
    np.testing.assert_array_equal(kicked, plain)
    # A constant acceleration a against a drag of rate r: v - target -> a / r, for half
    # kicks of 0.05 and 50 times the relaxation time.
    target = rng.standard_normal((5, 3))
    for half_rate in (0.05, 50.0):
        rate = np.full(5, 40.0)
        v = np.zeros((5, 3))
        for _ in range(4000):
            drag_kick(v, acceleration, rate, target, half_rate / 40.0)
        np.testing.assert_allclose(v - target, acceleration / 40.0, rtol=1e-10, atol=1e-13)


def _dragged(body, h, speed=0.2):
    rng = np.random.default_rng(7)
    rate = np.full(body.n_nodes, 10.0 / h)               # h rate / 2 = 5
    body.set_drag(rate, speed * rng.standard_normal(body.position.shape))
    return rate


@pytest.mark.parametrize("compiled", [True, False], ids=["compiled", "numpy"])
def test_a_lattice_body_keeps_its_volume_under_a_stiff_drag(compiled):
    body = body_3d(constraint=True)
    body.constraint_iterations, body.constraint_tolerance = 8, 1e-12
    body.compiled = compiled
    h = 0.5 * body.stability_limit()
    _dragged(body, h)
    body.fluid_force[:] = 1e-3
    for step in range(5):
        held = body.fluid_force.copy()
        start = body.position.copy()
        body.advance(step * 10 * h, 10 * h, h)
        mean_velocity = (body.position - start) / (10 * h)
        expected = held + (body.mass * body.drag_rate)[:, None] * (body.drag_target
                                                                   - mean_velocity)
        np.testing.assert_allclose(body.fluid_force, expected, rtol=1e-12, atol=1e-15)
        body.fluid_force[:] = held
        assert abs(body.volume_error()) < 1e-11
    # It moved: the drag set the nodes going towards their targets.
    assert np.abs(body.position - body_3d().position).max() > 1e-4


def test_compiled_and_numpy_substeps_agree_with_a_drag():
    bodies = [body_3d(constraint=True), body_3d(constraint=True)]
    bodies[1].compiled = False
    h = 0.5 * bodies[0].stability_limit()
    for body in bodies:
        body.constraint_iterations, body.constraint_tolerance = 8, 1e-12
        _dragged(body, h)
    for step in range(4):
        for body in bodies:
            body.fluid_force[:] = 0.0
            body.advance(step * 10 * h, 10 * h, h)
    np.testing.assert_allclose(bodies[0].position, bodies[1].position, rtol=0, atol=1e-15)
    np.testing.assert_allclose(bodies[0].velocity, bodies[1].velocity, rtol=1e-9, atol=1e-12)


def test_a_membrane_keeps_its_area_and_volume_within_1e_8_under_a_stiff_drag():
    from parmps.solids.mass_spring.model import MassSpringModel
    case = _case('shape = "capsule"\nradius = 1.0e-6\nlength = 2.0e-6\naxis = "x"\n'
                 'refinement = 3\n' + PULL.format(within=0.6e-6, force=5.0e-11))
    model = MassSpringModel.from_case(case)
    dt, body = case["time"]["fixed_dt"], model.bodies[0]
    h = model.substeps[body.name]
    # Targets of 0.2 mm/s: 20 nm a step against the cell's 1 um.
    _dragged(body, h, speed=2e-4)
    worst = 0.0
    for step in range(10):
        model.advance(step * dt, dt)
        model.check(step, (step + 1) * dt)
        worst = max(worst, abs(body.membrane.area_error(body.position)),
                    abs(body.volume_error()))
    assert worst <= 1e-8
    assert np.abs(body.velocity).max() > 5e-5            # the targets pull it
