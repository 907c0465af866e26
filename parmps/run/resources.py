"""What a case will ask of the machine, known before anything is allocated.

The particle count comes from the case's geometry alone (each fluid block,
tank and wall box is a rectangle of the lattice), so a case that would need
more memory than the machine has is refused with a sentence instead of dying
in an allocation.
"""

import math
import os

from parmps.core.settings import search_radius

# Fitted to the peak resident memory of the dam breaks on 2 ranks (the interpreter and
# libraries included; python -m parmps bench --ranks 2 --steps 10 --warmup 3, 2026-11-28):
# 2D, 1.01 M particles, 43 lattice neighbours within the search radius: 3.53 kB a
# particle; 3D (SPHERIC), 2.93 M particles, 212 neighbours: 6.79 kB. Per particle the
# fields, the step's copies and temporaries and the solver's vectors and coarse levels;
# per neighbour the pair index (8 bytes) and its share of the matrix entries (12 bytes
# each, within the Laplacian's radius, in the step's matrix and the one the
# preconditioner was set up on). The earlier 400 + 52 per neighbour put the 3D run at
# 31 GiB, which refused it on a 23.5 GiB machine, and the 2D one 25 % low.
_BYTES_PER_PARTICLE = 2700
_BYTES_PER_PAIR = 20


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
