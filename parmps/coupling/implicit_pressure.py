"""Coupling with the bodies' inertia in the pressure equation (docs/design.md §1.6).

Why. The weak coupling solves the pressure with the nodes moving as predicted
(``x + dt v``) and only then lets the pressure push them. The pressure is then
what it takes to move the fluid around nodes that will not give way; on a body
lighter than the fluid's added mass, the force that answers it overshoots by
about (added mass / body mass) each step and the exchange grows without bound
(the added-mass instability): box_in_flow blows up at solid/fluid density 0.3
and 0.1.

What. The nodes become particles of their own density in the pressure
equation, ``div (1/rho_i grad P) = source``: a node of mass m_i stands for a
particle of density rho_i = m_i / l0^d (the fluid force on it is -l0^d grad P,
so its acceleration is -grad P / rho_i), and pair ij's Laplacian weighs
(1/rho_i + 1/rho_j)/2 (:func:`parmps.fluid.schemes.laplacian.variable_density_poisson_rows`).
The pressure then accounts for how far the nodes give way: the fluid and the
nodes share one pressure solve, which is the implicit part a light body needs.
Springs, dashpots, loads and the area constraint stay explicit: after the
projection each body's owner advances it with the fluid force of the new
pressure held, exactly as in the weak coupling (the area multiplier acts on
the total force, so the area is kept as tightly). A node that cannot move
(pinned) is a wall to the pressure, weighed with the fluid's density as walls
are. Fluid-only neighbourhoods and bodies of the fluid's density give the
weak coupling's matrix exactly, so at density ratio 1 the two schemes agree
to round-off.

Viscosity. The viscous force on a node, ``k_i (u_bar_i - u_i)``, relaxes the node's
velocity towards its neighbours' at the rate k_i / m_i, which for a light node is rho0/rho_i
times the fluid's own (a node at density ratio 0.1 in box_in_flow: dt k/m = 3.3 per step,
beyond an explicit limit of 2). Either coupling takes it as a drag backward Euler in every
substep (:meth:`parmps.coupling.weak.WeakCoupling.node_forces`), stable at any rate.
"""

import numpy as np

from parmps.core.particles import SOLID
from parmps.coupling.weak import WeakCoupling


class ImplicitPressureCoupling(WeakCoupling):
    """The weak coupling's exchange with the nodes' inertia in the pressure equation."""

    # The pressure already answers a light node's motion: neither the weak scheme's warning
    # nor its added-mass diagnosis of a failure applies.
    ANSWERS_A_STEP_LATE = False

    def failure_cause(self, where=None):
        """For a light body: the explicit part of the exchange that still lags.

        The pressure answers a light node's motion, but the body's springs and area constraint
        act on the pressure force held over the step (the viscous drag is taken in the
        substeps since 2026-12-02: box_in_flow at density 0.001 and 1e-4 at 10 U0, which
        blew up before, then ran to 0.3 s; docs/history.md). In the stability map
        (docs/validation.md) every failure of box_in_flow under this scheme is a body
        lighter than the fluid in a fast flow (0.01 from 5 U0, 0.1 and 0.3 at 10 U0; density
        1 and 10 run at every speed): the fluid force grows by three orders or more within
        about 60 steps before a spring breaks. A step a quarter as long (time.dt_max = 5e-4
        instead of the Courant step near 2e-3 s) ran both 0.3 at 10 U0 and 0.01 at 5 U0 to
        the end: the lag per step is what grows.
        """
        light = self.light_bodies(where)
        if not light:
            return None
        return (f"{light} lighter than the fluid in a fast flow: under coupling.scheme = "
                f"\"implicit_pressure\" the pressure answers a light body's motion, but its "
                f"springs and area constraint still act on the pressure force held "
                f"over the step, and for a light body in a fast flow that lag grows from step "
                f"to step (the added-mass instability's explicit remainder; docs/validation.md, "
                f"Stability map). Shorten the step (time.dt_max) or make the body heavier")

    def pressure_mobility(self, particles):
        """rho0/rho_i of every local particle (ghosts too): 1 but on body nodes.

        Ghosts carry their body and node index, and every rank holds every
        body's masses, so no communication is needed.
        """
        mobility = np.ones(len(particles))
        nodes = np.flatnonzero(particles.kind == SOLID)
        mobility[nodes] = self.mobility_of(particles, nodes)
        return mobility
