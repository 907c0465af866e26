#!/usr/bin/env python3
"""The 3D gate at rest under its still water column: plane stress or plane strain?

    python validation/elastic_gate_3d/statics.py [--height 0.14]

Builds the gate of cases/elastic_gate_3d.toml, loads its face towards the water with
rho g (h - z) and solves its linear springs (parmps/tools/gate_statics.py). Prints the free
end's deflection at mid-width and along the width beside Euler-Bernoulli in plane stress and in
plane strain with the lattice's Poisson ratio (1/4), the fraction f of the way from the one to
the other, and the two limits the lattice reaches when the gate is made plane strain (every
node's sideways motion held) or a narrow strip (two nodes across): f = 1 and f = 0 if the
lattice bends right with 3 nodes through its thickness.
"""

import argparse
import logging
import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
ROOT = os.path.dirname(os.path.dirname(HERE))

from parmps import config, schema
from parmps.solids.mass_spring.build import build_bodies
from parmps.solids.mass_spring.statics import static_displacement, stiffness_matrix  # noqa
from parmps.tools import gate_statics

CASE = os.path.join(ROOT, "cases", "elastic_gate_3d.toml")
LATTICE_POISSON = 0.25
MID_WIDTH = [57, 58, 59, 60, 61, 62]  # the case's probe: tip row, j = 19 and 20


def gate(**changes):
    with open(CASE) as stream:
        raw = config.load_text(stream.read())
    raw["body"][0].update(changes)
    case = schema.validate(raw)
    (body,) = build_bodies(case)
    return body, case["body"][0]["youngs_modulus"]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--height", type=float, default=0.14, help="water column [m]")
    args = parser.parse_args()
    logging.disable(logging.WARNING)  # the lattice's Poisson ratio warning: stated above
    body, youngs = gate()
    result = gate_statics.gate_convention(body, args.height, youngs, LATTICE_POISSON,
                                          MID_WIDTH)
    held = np.zeros_like(body.position, bool)
    held[body.pinned] = True
    held[:, 1] = True
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    force = gate_statics.face_loads(body.position, gate_statics.lattice_spacing(body),
                                    args.height)
    strain = static_displacement(matrix, force, held)[0][MID_WIDTH, 0].mean()
    strip, _ = gate(ny=2)
    tip = np.flatnonzero(np.isclose(strip.position[:, 2], strip.position[:, 2].min()))
    narrow = gate_statics.gate_convention(strip, args.height, youngs, LATTICE_POISSON, tip)
    stress = result["plane_stress"]
    print(f"water column h = {args.height} m, E = {youngs:.4g} Pa, nu = {LATTICE_POISSON}")
    print(f"Euler-Bernoulli: plane stress {1e3 * stress:.3f} mm, plane strain "
          f"{1e3 * result['plane_strain']:.3f} mm")
    print(f"3D gate, mid-width: {1e3 * result['lattice']:.3f} mm, f = {result['fraction']:.3f}")
    across = result["across"]
    print(f"3D gate, side edges: {1e3 * across[0]:.3f} mm; along the width (mm): "
          + " ".join(f"{1e3 * v:.2f}" for v in across[::5]))
    print(f"limits: sideways motion held f = {(1 - strain / stress) / LATTICE_POISSON ** 2:.3f},"
          f" a strip two nodes wide f = {narrow['fraction']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
