"""What a case will ask of the machine, known before anything is allocated.

The particle count comes from the case's geometry alone (each fluid block and
wall box is a rectangle of the lattice, a tank its walls' boxes, a shaped wall a
band about its bounding box), so a case that would need more memory than the
machine has is refused with a sentence instead of dying in an allocation.
"""

import math
import os

import numpy as np

from parmps.geometry.domain import Domain
from parmps.geometry.scene import tank_material
from parmps.geometry.walls import shape_bounds


# Fitted to the peak resident memory of the dam breaks on 2 ranks (the interpreter and
# libraries included; python -m parmps bench [--scene dam_break_3d] --particles 1000000
# --ranks 2 --steps 10 --warmup 3 [--set mps.re_laplacian=R], 2026-11-29), per particle
# A + B x the lattice neighbours within the Laplacian's radius: the pairs the step holds at
# its peak are the sub-lists within that radius, the step's matrix's entries (12 bytes
# each) and the preconditioner's hierarchy (GAMG holds no other system's matrix).
# 2D, 1.01 M particles: 2,345 bytes a particle at 3.1 l0 (30 neighbours), 3,037 at 4.0
# (50). 3D (SPHERIC, 972k): 2,502 at 2.3 l0 (51), 4,288 at 3.1 (125); at 4.96 M and 2.3 l0
# 2,572. A 3D tank's dummies and dry walls hold no rows and no lists, so its share per
# particle is smaller than 2D's.
_BYTES_PER_PARTICLE = {2: 1304, 3: 1269}
_BYTES_PER_NEIGHBOUR = {2: 34.5, 3: 24.2}


def particle_estimate(case):
    """About how many particles the case's geometry makes (walls and dummies included)."""
    spacing = case["particles"]["spacing"]
    if spacing is None:
        return sum(max(spec["nx"], 1) * max(spec["ny"], 1) for spec in case.get("body", ()))
    area = 0.0
    d = case.get("dimension", 2)
    for block in case.get("fluid_block", ()):
        # A block of a shape or a mesh: its bounding box (a mesh's when clipped, else 0).
        box = shape_bounds(block) if block.get("shape") or block.get("mesh") else \
            (block["lower"], block["upper"])
        if box is not None:
            area += math.prod(u - l for u, l in zip(box[1], box[0]))
    for spec in case.get("wall", ()):
        box = shape_bounds(spec)
        if box is not None:
            # The layers' shell about the bounding box, an upper bound of the band.
            thick = (spec["wall_layers"] + spec["dummy_layers"]) * spacing
            area += math.prod(u - l + 2 * thick for u, l in zip(box[1], box[0])) - \
                math.prod(max(u - l - 2 * thick, 0.0) for u, l in zip(box[1], box[0]))
    domain = Domain.from_case(case)
    for spec in case.get("tank", ()):
        # The walls' outer box (the tank's own geometry), less the inner box.
        boxes = [(np.asarray(spec["lower"]), np.asarray(spec["upper"]))] + \
            [(lower, upper) for lower, upper, _ in tank_material(spec, spacing, domain)]
        outer = np.max([u for _, u in boxes], axis=0) - np.min([l for l, _ in boxes], axis=0)
        area += math.prod(outer) - math.prod(np.subtract(spec["upper"], spec["lower"]))
    for spec in case.get("wall_box", ()):
        area += math.prod(u - l for u, l in zip(spec["upper"], spec["lower"]))
    for spec in case.get("inlet", ()):
        area += math.prod(u - l for u, l in zip(spec["upper"], spec["lower"]))
    return area / spacing ** d


def memory_estimate(case):
    """Bytes a run of the case needs, about (the pair lists, the matrix and its solver's
    set-up, which grow with the neighbours within the Laplacian's radius)."""
    particles = particle_estimate(case)
    spacing = case["particles"]["spacing"]
    if spacing is None:
        # Bodies alone: no pair lists and no pressure solve; the larger share a particle.
        return particles * max(_BYTES_PER_PARTICLE.values())
    # Lattice neighbours within the Laplacian's radius: the volume of a d-ball of it.
    d = case.get("dimension", 2)
    neighbours = math.pi ** (d / 2) / math.gamma(d / 2 + 1) * case["mps"]["re_laplacian"] ** d
    return particles * (_BYTES_PER_PARTICLE[d] + neighbours * _BYTES_PER_NEIGHBOUR[d])


def machine_memory():
    """Physical memory of this machine in bytes (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None
