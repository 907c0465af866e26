"""Run-time guards: stop a run that has gone wrong with the step and the cause.

The time loops call these after every step. Each check is vectorised over the
owned particles or nodes (a handful of comparisons per particle), so it costs
far less than the step it guards. Every check raises :class:`RunFailure`
(exit status 1) on every rank together: the verdict is reduced over the
communicator before anyone raises.

- :func:`wall_rectangles` and :func:`check_wall_penetration`: a fluid particle
  whose centre lies inside the material of a tank wall or a wall box. The
  particles of a wall model a surface half a spacing in front of their first
  layer; a fluid particle in contact sits half a spacing on the other side. One
  whose centre is deeper than ``WALL_MARGIN`` behind the surface sits on the
  wall's own particles: the wall has leaked. A particle cannot cross a whole
  wall (at least two wall layers plus dummies) between two checks without a
  Courant number above 1, which the time loop stops first.
- :func:`check_shaped_walls`: the same for the walls of any shape (``[[wall]]``), by
  their surface's signed distance (:class:`parmps.geometry.walls.MaterialDepth`).
- a blown-up body is the solid model's own check (``SolidModel.check``; for
  mass-spring bodies :mod:`parmps.solids.mass_spring.model`).
"""

import numpy as np

from parmps.errors import RunFailure
from parmps.core.geometry import first_box_holding, format_point
from parmps.core.particles import FLUID
from parmps.boundaries.walls import travel
from parmps.geometry.domain import Domain
from parmps.geometry.scene import tank_material

# Depth behind a wall surface, in spacings, past which a fluid particle has
# leaked: half a spacing puts its centre on the first wall layer's centre line.
WALL_MARGIN = 0.5

# A tank's side walls along each horizontal axis (lower side, upper side), for messages.
SIDE_NAMES = (("left wall", "right wall"), ("front wall", "back wall"))


def wall_rectangles(case, time=0.0):
    """The wall material at ``time`` as boxes ``(lower, upper, name)``, in metres.

    A tank gives its side walls (left and right, and in 3D front and back) and its
    bottom (and top when closed), each as thick as its wall and dummy layers, bar those
    across a periodic axis it spans (:func:`parmps.geometry.scene.tank_material`); a
    wall box is its own box. Moving tanks and boxes (parmps.boundaries.walls) are
    where their motion has taken them.
    """
    spacing = case["particles"]["spacing"]
    domain = Domain.from_case(case)
    rectangles = []
    for k, spec in enumerate(case.get("tank", ())):
        shift = travel(spec, time)
        for lower, upper, (axis, side) in tank_material(spec, spacing, domain, shift):
            if axis == len(lower) - 1:
                label = f"tank[{k}] {('bottom', 'top')[side]}"
            else:
                label = f"tank[{k}] {SIDE_NAMES[axis][side]}"
            rectangles.append((tuple(lower), tuple(upper), label))
    for k, spec in enumerate(case.get("wall_box", ())):
        shift = travel(spec, time)
        rectangles.append((tuple(np.add(spec["lower"], shift)),
                           tuple(np.add(spec["upper"], shift)), f"wall_box[{k}]"))
    return rectangles


def inside_rectangles(position, rectangles, margin, mask=None):
    """Index of the first box (shrunk by ``margin``) holding each point, or -1 (and -1 for
    the points ``mask`` leaves out)."""
    d = np.shape(position)[1]
    lower = np.array([np.add(lower, margin) for lower, _, _ in rectangles]).reshape(-1, d)
    upper = np.array([np.subtract(upper, margin) for _, upper, _ in rectangles]).reshape(-1, d)
    return first_box_holding(position, lower, upper, mask)


def check_shaped_walls(particles, walls, case, time, spacing, comm, step, source_settings=()):
    """Stop if an owned fluid particle sits deeper than WALL_MARGIN in the material of a
    wall of any shape (``walls``: a MaterialDepth of the case's [[wall]]s)."""
    if not walls:
        return
    n = particles.n_owned
    fluid = np.flatnonzero(particles.kind[:n] == FLUID)
    shifts = [travel(spec, time) for spec in case["wall"]]
    depth, which = walls.depth(particles.position[fluid], shifts)
    inside = np.full(n, -1, np.int64)
    leaked = depth > WALL_MARGIN * spacing
    inside[fluid[leaked]] = which[leaked]
    _report(particles, inside, [walls.label(k) for k in range(len(case["wall"]))], comm,
            step, source_settings)


def check_wall_penetration(particles, rectangles, spacing, comm, step, source_settings=()):
    """Stop if an owned fluid particle sits inside wall material (see the module notes);
    ``source_settings``: the case's PPE source's settings that strengthen it, named in the
    message beside the compressibility."""
    if not rectangles:
        return
    n = particles.n_owned
    position = particles.position[:n]
    which = inside_rectangles(position, rectangles, WALL_MARGIN * spacing,
                              mask=particles.kind[:n] == FLUID)
    _report(particles, which, [name for _, _, name in rectangles], comm, step,
            source_settings)


def _report(particles, which, names, comm, step, source_settings):
    """Raise, on every rank alike, if an owned particle has a wall in ``which`` (its index
    into ``names``, -1 for none)."""
    position = particles.position[:particles.n_owned]
    hit = np.flatnonzero(which >= 0)
    local = None
    if len(hit):
        first = hit[np.argmin(particles.id[hit])]
        local = (int(particles.id[first]), int(which[first]), tuple(position[first]),
                 len(hit))
    found = [item for item in comm.allgather(local) if item is not None]
    if found:
        pid, k, point, _ = min(found)
        count = sum(item[3] for item in found)
        raise RunFailure(
            f"step {step}: fluid particle {pid} went through a wall: it is inside "
            f"{names[k]} at {format_point(point, '.4g')} ({count} fluid particles inside "
            f"walls); "
            f"the wall's pressure did not hold it back (weak PPE source: "
            f"{', '.join([*source_settings, 'mps.compressibility'])}) or the step is too "
            f"long for the flow (lower time.dt_max or time.cfl)", where=point)
