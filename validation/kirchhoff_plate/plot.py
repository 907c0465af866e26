#!/usr/bin/env python3
"""The clamped lattice plate's centre deflection against Kirchhoff over a/t and the nodes
through the thickness (statics on a quadrant; about a minute).

    python validation/kirchhoff_plate/plot.py [--png docs/kirchhoff_plate.png]

Prints one line per plate and plots the relative error against (t/a)^2: thin-plate theory
leaves out shear deformation, which grows as (t/a)^2; what remains at t/a -> 0 is the
lattice's own (its twisting stiffness, docs/elastic_lattice.md).
"""

import argparse

from parmps.tools import elastic_3d

PLATES = {3: (20, 30, 40), 4: (20, 30, 40)}  # nodes through t -> a/t


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--png", default=None)
    args = parser.parse_args()
    rows = {}
    for nodes, ratios in PLATES.items():
        for ratio in ratios:
            result = elastic_3d.clamped_plate(ratio * (nodes - 1), nodes)
            rows[nodes, ratio] = result["error"]
            print(f"a/t = {ratio}, {nodes} nodes through t: {100 * result['error']:+.2f} % "
                  f"({result['nodes']} nodes in the quadrant)", flush=True)
    if args.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(5.5, 3.4))
        for nodes, ratios in PLATES.items():
            ax.plot([1e3 / r ** 2 for r in ratios], [100 * rows[nodes, r] for r in ratios], "o-",
                    label=f"{nodes} nodes through t")
        ax.set_xlim(left=0)
        ax.set_ylim(0, 5.5)
        ax.axhline(5, color="gray", lw=0.8, ls="--", label="tolerance")
        ax.set_xlabel("1000 (t/a)$^2$")
        ax.set_ylabel("centre deflection / Kirchhoff - 1 [%]")
        ax.legend(fontsize=8)
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)


if __name__ == "__main__":
    main()
