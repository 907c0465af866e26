"""What a case will ask of the machine, known before anything is allocated.

The particle count comes from the case's geometry alone (each fluid block,
tank and wall box is a rectangle of the lattice), so a case that would need
more memory than the machine has is refused with a sentence instead of dying
in an allocation.
"""

import math
import os

from parmps.core.settings import search_radius

# Per particle: the fields (~80 bytes), a step's temporaries (~320 bytes), and per
# neighbour within the search radius the pair index (8 bytes), its share of the pair
# geometry and of the kernels' temporaries (24) and of the matrix entry (12 + 8).
_BYTES_PER_PARTICLE = 400
_BYTES_PER_PAIR = 52


def particle_estimate(case):
    """About how many particles the case's geometry makes (walls and dummies included)."""
    spacing = case["particles"]["spacing"]
    if spacing is None:
        return sum(max(spec["nx"], 1) * max(spec["ny"], 1) for spec in case.get("body", ()))
    area = 0.0
    for block in case.get("fluid_block", ()):
        area += math.prod(u - l for u, l in zip(block["upper"], block["lower"]))
    for spec in case.get("tank", ()):
        thick = (spec["wall_layers"] + spec["dummy_layers"]) * spacing
        inner = [u - l for u, l in zip(spec["upper"], spec["lower"])]
        # The walls' outer box, less the inner box (the roof's layers when closed).
        outer = [e + 2 * thick for e in inner[:-1]] + \
            [inner[-1] + thick * (1 if spec["open_top"] else 2)]
        area += math.prod(outer) - math.prod(inner)
    for spec in case.get("wall_box", ()):
        area += math.prod(u - l for u, l in zip(spec["upper"], spec["lower"]))
    for spec in case.get("inlet", ()):
        area += math.prod(u - l for u, l in zip(spec["upper"], spec["lower"]))
    return area / spacing ** case.get("dimension", 2)


def memory_estimate(case):
    """Bytes a run of the case needs, about (pair lists dominate)."""
    particles = particle_estimate(case)
    spacing = case["particles"]["spacing"]
    if spacing is None:
        return particles * _BYTES_PER_PARTICLE
    # Lattice neighbours within the search radius: the volume of a d-ball of that radius.
    d = case.get("dimension", 2)
    neighbours = math.pi ** (d / 2) / math.gamma(d / 2 + 1) * (search_radius(case) / spacing) ** d
    return particles * (_BYTES_PER_PARTICLE + neighbours * _BYTES_PER_PAIR)


def machine_memory():
    """Physical memory of this machine in bytes (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None
