"""The fluid's mechanical energy: what a long run is checked by (docs/design.md §1.8).

A free-surface flow with fixed walls and no inflow only loses mechanical energy (kinetic
plus potential, the bodies' kinetic and elastic energy included): a rise that no inlet,
outlet or moving wall paid for is a numerical source. Each fluid particle stands for the
mass ``rho l0^d``; the potential energy is measured from a datum, the point of the initial
fluid lowest along gravity, so a still column's energy is its own and a 1 % rise means 1 %
of what the flow has to spend.

Along a periodic axis a body force has no potential (a particle that goes round the
period comes back lower): there its power, ``sum m g.u``, is integrated over the steps
and counted with the work done on the fluid.
"""

import numpy as np

from parmps.core.particles import FLUID


def particle_energy(velocity, position, mass, gravity, datum):
    """Kinetic and potential energy of the particles given (rows of ``velocity`` and
    ``position``), each of mass ``mass``: ``(sum m |u|^2 / 2, -sum m g.(x - datum))``."""
    kinetic = 0.5 * mass * float(np.einsum("ij,ij->", velocity, velocity))
    potential = -mass * float(np.sum((position - datum) @ gravity))
    return kinetic, potential


def fluid_energy(particles, mass, gravity, datum, mask=None):
    """This rank's ``(kinetic, potential)`` energy of its owned fluid particles (or of the
    owned particles ``mask`` selects); not reduced over the ranks."""
    n = particles.n_owned
    if mask is None:
        mask = particles.kind[:n] == FLUID
    return particle_energy(particles.velocity[:n][mask], particles.position[:n][mask],
                           mass, gravity, datum)


def split_body_force(gravity, periodic):
    """``(gravity with a potential, the rest)``: the components along the ``periodic`` axes
    go to the second, which is None when it is zero."""
    gravity = np.asarray(gravity, dtype=float)
    drive = np.zeros_like(gravity)
    drive[list(periodic)] = gravity[list(periodic)]
    if not np.any(drive):
        return gravity, None
    return gravity - drive, drive


def body_force_power(particles, mass, force, mask=None):
    """This rank's power ``sum m f.u`` of the body force ``force`` on its owned fluid (or
    the owned particles ``mask`` selects); not reduced over the ranks."""
    n = particles.n_owned
    if mask is None:
        mask = particles.kind[:n] == FLUID
    return mass * float(np.sum(particles.velocity[:n][mask] @ force))


def rise_scale(initial, row):
    """What a rise of the budget is measured against: the larger of the fluid's initial
    energy |E0| and the work done on it so far (the row's |boundary work|). That is E0 for a
    flow that starts with its energy (a dam break); for one that starts at rest with nothing
    to fall (a channel driven by a body force, a sheared lid) it is what has been given to
    it, so round-off on a zero is not taken for a source."""
    return max(abs(initial), abs(row["boundary_work"]))


def budget(row):
    """What can only fall in a flow with fixed walls and no inflow: the fluid's and the
    bodies' energy less the work the boundaries did, from a diagnostics row (or columns)."""
    return row["fluid_energy"] + row.get("body_energy", 0.0) - row["boundary_work"]


def energy_datum(particles, gravity, comm):
    """The owned fluid's lowest point along ``gravity`` over every rank (collective):
    the origin of the potential energy. The origin itself, 0, where there is no gravity
    or no fluid."""
    from mpi4py import MPI
    dimension = particles.position.shape[1]
    g = np.linalg.norm(gravity)
    if g == 0.0:
        return np.zeros(dimension)
    down = np.asarray(gravity, dtype=float) / g
    n = particles.n_owned
    fluid = particles.kind[:n] == FLUID
    depth = float((particles.position[:n][fluid] @ down).max()) if fluid.any() else -np.inf
    depth = comm.allreduce(depth, op=MPI.MAX)
    return down * depth if np.isfinite(depth) else np.zeros(dimension)
