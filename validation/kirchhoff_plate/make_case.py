#!/usr/bin/env python3
"""Write validation/kirchhoff_plate/plate.toml: the clamped square plate, a/t = 40.

    python validation/kirchhoff_plate/make_case.py [--cells 120] [--thickness-nodes 4]

A lattice body can pin one named side; a plate clamped on four sides lists their nodes
(pinned_ids), which this script generates rather than a person typing them.
"""

import argparse
import os

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))

HEADER = """title = "Clamped square plate under uniform pressure (Kirchhoff), a/t = {ratio:g}"

# Written by validation/kirchhoff_plate/make_case.py. A 3D lattice plate given by its material
# (docs/elastic_lattice.md, "3D"), {n} x {n} x {nt} nodes: side a = {side:g} m, thickness
# t = {thickness:g} m between the outer nodes, clamped on its four side faces, a pressure
# q = {pressure:g} Pa on its top face (q spacing^2 per top node; the edge nodes are held).
# Kirchhoff: w = 0.00126 q a^4 / D, D = E t^3/12(1 - nu^2), nu = 1/4 (the lattice's).
# The validation is static (parmps.tools.analysis.kirchhoff_plate): run dynamically, the
# plate would swing about that deflection.
[domain]
lower = [-0.05, -0.05, -0.05]
upper = [{upper:g}, {upper:g}, 0.07]

[physics]
gravity = [0.0, 0.0, 0.0]

[time]
end = 0.01
fixed_dt = 1.0e-3

[[body]]
name = "plate"
type = "lattice"
nx = {n}
ny = {n}
nz = {nt}
spacing = {spacing!r}
lower = [0.0, 0.0, 0.0]
youngs_modulus = 1.0e7     # [Pa]
density = 1000.0           # [kg/m^3]
damping_ratio = 0.2        # of the lattice's highest mode
volume_constraint = false
"""

LOAD = """
[[body.load]]              # the pressure, per top node
nodes = "top"
force = [0.0, 0.0, {force!r}]
start = 0.0
end = 10.0
ramp = 0.001
"""


def side_face_ids(n, nt):
    """Node ids (i + n j + n^2 k) on the faces i = 0, n - 1 and j = 0, n - 1."""
    k, j, i = np.indices((nt, n, n)).reshape(3, -1)
    side = (i == 0) | (i == n - 1) | (j == 0) | (j == n - 1)
    return np.flatnonzero(side)


def case_text(cells, thickness_nodes, thickness=0.02, pressure=1000.0):
    n, spacing = cells + 1, thickness / (thickness_nodes - 1)
    side = cells * spacing
    text = HEADER.format(ratio=side / thickness, n=n, nt=thickness_nodes, side=side,
                         thickness=thickness, pressure=pressure, upper=side + 0.05,
                         spacing=spacing)
    ids = [str(v) for v in side_face_ids(n, thickness_nodes)]
    lines = [", ".join(ids[k:k + 16]) for k in range(0, len(ids), 16)]
    text += "pinned_ids = [             # the four side faces, through the thickness: clamped\n"
    text += ",\n".join("    " + line for line in lines) + "]\n"
    return text + LOAD.format(force=-pressure * spacing ** 2)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=120, help="spacings across the side (even)")
    parser.add_argument("--thickness-nodes", type=int, default=4)
    parser.add_argument("--out", default=os.path.join(HERE, "plate.toml"))
    args = parser.parse_args()
    with open(args.out, "w") as handle:
        handle.write(case_text(args.cells, args.thickness_nodes))


if __name__ == "__main__":
    main()
