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
- a blown-up body is the solid model's own check (``SolidModel.check``; for
  mass-spring bodies :mod:`parmps.solids.mass_spring.model`).
"""

import numpy as np

from parmps.errors import RunFailure
from parmps.core.particles import FLUID
from parmps.boundaries.walls import travel

# Depth behind a wall surface, in spacings, past which a fluid particle has
# leaked: half a spacing puts its centre on the first wall layer's centre line.
WALL_MARGIN = 0.5

def wall_rectangles(case, time=0.0):
    """The wall material at ``time`` as rectangles ``(lower, upper, name)``, in metres.

    A tank gives its left, right and bottom walls (and top when closed), each
    as thick as its wall and dummy layers; a wall box is its own rectangle.
    Moving tanks and boxes (parmps.boundaries.walls) are where their motion has taken them.
    """
    spacing = case["particles"]["spacing"]
    rectangles = []
    for k, spec in enumerate(case.get("tank", ())):
        shift = travel(spec, time)
        (x0, y0), (x1, y1) = np.add(spec["lower"], shift), np.add(spec["upper"], shift)
        thick = (spec["wall_layers"] + spec["dummy_layers"]) * spacing
        top = y1 if spec["open_top"] else y1 + thick
        name = f"tank[{k}]"
        rectangles.append(((x0 - thick, y0 - thick), (x0, top), f"{name} left wall"))
        rectangles.append(((x1, y0 - thick), (x1 + thick, top), f"{name} right wall"))
        rectangles.append(((x0 - thick, y0 - thick), (x1 + thick, y0), f"{name} bottom"))
        if not spec["open_top"]:
            rectangles.append(((x0 - thick, y1), (x1 + thick, y1 + thick), f"{name} top"))
    for k, spec in enumerate(case.get("wall_box", ())):
        shift = travel(spec, time)
        rectangles.append((tuple(np.add(spec["lower"], shift)),
                           tuple(np.add(spec["upper"], shift)), f"wall_box[{k}]"))
    return rectangles


def inside_rectangles(position, rectangles, margin):
    """Index of the first rectangle (shrunk by ``margin``) holding each point, or -1."""
    which = np.full(len(position), -1, np.int64)
    x, y = position[:, 0], position[:, 1]
    # Few rectangles, many points: loop over the rectangles, vectorise the points.
    for k, (lower, upper, _) in reversed(list(enumerate(rectangles))):
        inside = ((x > lower[0] + margin) & (x < upper[0] - margin) &
                  (y > lower[1] + margin) & (y < upper[1] - margin))
        which[inside] = k
    return which


def check_wall_penetration(particles, rectangles, spacing, comm, step):
    """Stop if an owned fluid particle sits inside wall material (see the module notes)."""
    if not rectangles:
        return
    n = particles.n_owned
    fluid = particles.kind[:n] == FLUID
    position = particles.position[:n][fluid]
    which = inside_rectangles(position, rectangles, WALL_MARGIN * spacing)
    hit = which >= 0
    local = None
    if np.any(hit):
        ids = particles.id[:n][fluid][hit]
        first = int(np.argmin(ids))
        x, y = position[hit][first]
        local = (int(ids[first]), int(which[hit][first]), float(x), float(y),
                 int(np.count_nonzero(hit)))
    found = [item for item in comm.allgather(local) if item is not None]
    if found:
        pid, k, x, y, _ = min(found)
        count = sum(item[4] for item in found)
        raise RunFailure(
            f"step {step}: fluid particle {pid} went through a wall: it is inside "
            f"{rectangles[k][2]} at ({x:.4g}, {y:.4g}) ({count} fluid particles inside walls); "
            f"the wall's pressure did not hold it back (weak PPE source: mps.density.relaxation, "
            f"mps.compressibility) or the step is too long for the flow (lower time.dt_max "
            f"or time.cfl)", where=(x, y))
