#!/usr/bin/env python3
"""Where a still tank's pressure error sits: each particle's time-averaged pressure as the
height where a field of slope rho g through it is zero, z + P/(rho g), in l0.

    python validation/hydrostatic_3d/profile.py OUT/result.h5 [--settle 0.5]

Prints that height by layer (1 l0 bins of the time-averaged height) for the fluid away from
the side walls, the fluid beside them and the side walls' first layer, and the fraction of the
fluid taken for free surface (n* < beta n0, the run's own test) near the top. A pressure exactly hydrostatic and
zero where the water ends reads the water's depth in every row (docs/validation/
hydrostatic_3d.md). Works for the 2D tank too (y up).
"""

import argparse

import numpy as np


def profile(path, settle_time):
    """(rows of (group, height bin, count, zero height), surface rows of (height bin,
    fraction flagged), the water's depth), heights in l0 above the water's floor."""
    from parmps.core.particles import FLUID, WALL
    from parmps.fluid.constants import MPSConstants
    from parmps.io.frames import read_frames
    from parmps.tools.analysis import fluid_extent, gravity, result_case

    # The case as run, its defaults filled in: the surface test the run itself made.
    case = result_case(path)
    spacing = case["particles"]["spacing"]
    lower, upper = fluid_extent(case)
    g, density = gravity(case), case["fluid"]["density"]
    surface_density = case["mps"]["surface_threshold"] * MPSConstants.from_case(case).n0
    # Frames come sorted by id, so particle k is the same particle in every frame.
    frames = [f for f in read_frames(path) if f["time"] >= settle_time]
    if not frames:
        raise SystemExit(f"{path}: no frame after t = {settle_time} s")
    kind = frames[0]["kind"]
    position = np.mean([f["position"] for f in frames], axis=0)
    pressure = np.mean([f["pressure"] for f in frames], axis=0)
    height = (position[:, -1] - lower[-1]) / spacing
    zero = height + pressure / (density * g * spacing)
    horizontal = position[:, :-1]
    # Distance in l0 to the nearest side wall's face; negative inside the walls.
    side = np.min(np.concatenate([horizontal - lower[:-1], upper[:-1] - horizontal], axis=1),
                  axis=1) / spacing
    groups = (("fluid away from the side walls", (kind == FLUID) & (side > 1.2)),
              ("fluid beside a side wall", (kind == FLUID) & (side <= 1.2)),
              ("first side-wall layer", (kind == WALL) & (side > -1.0) & (side < 0.0)))
    depth = (upper[-1] - lower[-1]) / spacing
    rows = []
    for name, chosen in groups:
        for bottom in np.arange(0.0, depth + 2.0):
            here = chosen & (height >= bottom) & (height < bottom + 1.0)
            if np.any(here):
                rows.append((name, bottom, int(np.count_nonzero(here)),
                             float(zero[here].mean())))
    # Half-l0 bins of the instantaneous height near the top, over every frame.
    edges = np.arange(depth - 3.0, depth + 1.01, 0.5)
    counted, surface = np.zeros(len(edges) - 1), np.zeros(len(edges) - 1)
    for frame in frames:
        fluid = frame["kind"] == FLUID
        z = (frame["position"][fluid, -1] - lower[-1]) / spacing
        counted += np.histogram(z, edges)[0]
        surface += np.histogram(z[frame["number_density"][fluid] < surface_density], edges)[0]
    flagged = [(bottom, taken / total)
               for bottom, total, taken in zip(edges[:-1], counted, surface) if total]
    return rows, flagged, depth


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("result", help="result.h5 of a still tank")
    parser.add_argument("--settle", type=float, default=0.5, help="average from this time [s]")
    args = parser.parse_args()
    rows, flagged, depth = profile(args.result, args.settle)
    print(f"water depth {depth:.2f} l0; z + P/(rho g) in l0, time-averaged from {args.settle} s")
    for name, bottom, count, zero in rows:
        print(f"{name:32s} {bottom:5.1f}-{bottom + 1:5.1f} l0  {count:5d} particles  "
              f"P = 0 at {zero:7.3f} l0")
    for bottom, fraction in flagged:
        print(f"fluid at {bottom:5.1f}-{bottom + 0.5:5.1f} l0: {100 * fraction:5.1f} % taken for "
              f"free surface")


if __name__ == "__main__":
    main()
