#!/usr/bin/env python3
"""Clamped elastic lattice cantilever against Euler-Bernoulli beam theory, under refinement.

Usage: python scripts/verify_cantilever.py [--slenderness 10] [--nodes 4 6 8 12]
                                           [--dynamic 4 6 8] [--out docs]

For each number of nodes through the depth: the static tip deflection under a
tip load and under the beam's own weight (direct linear solve of its springs),
the first natural frequency from the time integrator (for --dynamic counts)
and from the lattice's lowest eigenvalue. The same for the other reading of a
lattice (explicit springs, every node a full cell, h = ny a), for comparison.
Writes <out>/cantilever.png and prints the errors; the beam and the references
are in parmps.tools.cantilever.
"""

import argparse
import json
import pathlib
import time

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from parmps.tools import cantilever  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]


def measure(nodes, dynamic, slenderness, node_cells=False):
    reference = cantilever.beam_theory(slenderness)
    rows = []
    for ny in nodes:
        start = time.perf_counter()
        tip = cantilever.static_tip_deflection(ny, slenderness, tip_load=cantilever.TIP_LOAD,
                                               node_cells=node_cells)
        weight = cantilever.static_tip_deflection(ny, slenderness, gravity=cantilever.GRAVITY,
                                                  node_cells=node_cells)
        eigen = cantilever.lattice_first_frequency(ny, slenderness, node_cells=node_cells)
        row = {"ny": ny, "tip_load": tip / reference["tip_load"] - 1.0,
               "gravity": weight / reference["gravity"] - 1.0,
               "omega_eigen": eigen / reference["omega"] - 1.0}
        if ny in dynamic and not node_cells:
            omega, substeps = cantilever.first_frequency(ny, slenderness, periods=6.0)
            row.update(omega_dynamic=omega / reference["omega"] - 1.0, substeps=substeps)
        row["seconds"] = time.perf_counter() - start
        rows.append(row)
    return rows


def plot(rows, alternative, slenderness, path):
    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 4))
    nodes = [row["ny"] for row in rows]
    left.plot(nodes, [100 * row["tip_load"] for row in rows], "o-", label="tip load")
    left.plot(nodes, [100 * row["gravity"] for row in rows], "s-", label="own weight")
    left.plot(nodes, [100 * row["tip_load"] for row in alternative], "o--", color="grey",
              label="tip load, node cells (h = ny a)")
    # The bending stiffness with the edge lines at k_a/2 and nothing moved inwards:
    # E2 t (h^3 + 5/4 a^2 h)/12 (docs/elastic_lattice.md), shear deformation left out.
    excess = [1.0 + 5.0 / (4.0 * (ny - 1) ** 2) for ny in nodes]
    left.plot(nodes, [100 * (1.0 / e - 1.0) for e in excess], ":", color="tab:red",
              label="edge lines at k_a/2 only (derived)")
    right.plot(nodes, [100 * (e ** 0.5 - 1.0) for e in excess], ":", color="tab:red",
               label="edge lines at k_a/2 only (derived)")
    left.set_ylabel("tip deflection error vs Euler-Bernoulli [%]")
    dynamic = [row for row in rows if "omega_dynamic" in row]
    right.plot([row["ny"] for row in dynamic], [100 * row["omega_dynamic"] for row in dynamic],
               "o-", label="time integrator")
    right.plot(nodes, [100 * row["omega_eigen"] for row in rows], "x:",
               label="lattice eigenvalue")
    right.plot(nodes, [100 * row["omega_eigen"] for row in alternative], "x--", color="grey",
               label="eigenvalue, node cells (h = ny a)")
    right.set_ylabel("first frequency error [%]")
    for axis in (left, right):
        axis.axhspan(-5, 5, color="tab:green", alpha=0.1, lw=0)
        axis.axhline(0.0, color="k", lw=0.6)
        axis.set_xlabel("nodes through the depth")
        axis.set_xticks(nodes)
        axis.legend(fontsize=8)
        axis.grid(alpha=0.3)
    figure.suptitle(f"Clamped lattice cantilever, L/h = {slenderness}, E = 10 MPa "
                    f"(plane strain, nu = 1/4): errors against beam theory (band: 5 %)",
                    fontsize=9)
    figure.tight_layout()
    figure.savefig(path, dpi=120)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[1])
    parser.add_argument("--slenderness", type=int, default=10, help="L/h")
    parser.add_argument("--nodes", type=int, nargs="+", default=[4, 6, 8, 12])
    parser.add_argument("--dynamic", type=int, nargs="*", default=[4, 6, 8],
                        help="node counts whose frequency is also timed with the integrator")
    parser.add_argument("--out", type=pathlib.Path, default=ROOT / "docs")
    args = parser.parse_args()
    rows = measure(args.nodes, args.dynamic, args.slenderness)
    alternative = measure(args.nodes, (), args.slenderness, node_cells=True)
    args.out.mkdir(parents=True, exist_ok=True)
    plot(rows, alternative, args.slenderness, args.out / "cantilever.png")
    print(f"L/h = {args.slenderness}; errors against Euler-Bernoulli (negative: stiffer)")
    print(" ny   tip load   own weight   omega (integrator)   omega (eigenvalue)   "
          "node cells: tip load, omega")
    for row, other in zip(rows, alternative):
        dynamic = (f"{100 * row['omega_dynamic']:+8.2f} %" if "omega_dynamic" in row
                   else "       -  ")
        print(f"{row['ny']:3d}  {100 * row['tip_load']:+7.2f} %  {100 * row['gravity']:+8.2f} %"
              f"   {dynamic}           {100 * row['omega_eigen']:+7.2f} %          "
              f"{100 * other['tip_load']:+7.2f} %, {100 * other['omega_eigen']:+6.2f} %")
    print(json.dumps({"slenderness": args.slenderness, "elastic": rows,
                      "node_cells": alternative}))


if __name__ == "__main__":
    main()
