#!/usr/bin/env python3
"""The 3D lattice cantilever against Euler-Bernoulli at several resolutions (statics and the
sparse eigen solve; no time integration).

    python validation/cantilever_3d/verify.py [--nodes 4 6 8] [--slenderness 20]

Prints a markdown table of the relative errors of the static tip deflection under a tip
load and under the beam's weight, and of omega_1 (parmps.tools.elastic_3d).
"""

import argparse

from parmps.tools import elastic_3d


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, nargs="+", default=[4, 6, 8])
    parser.add_argument("--slenderness", type=float, default=20)
    args = parser.parse_args()
    rows = {nodes: elastic_3d.cantilever_errors(nodes, args.slenderness) for nodes in args.nodes}
    print(f"L/h = {args.slenderness:g}\n")
    print("| nodes through the depth | " + " | ".join(map(str, rows)) + " |")
    print("|---|" + "---|" * len(rows))
    for key, label in (("tip_load", "tip deflection, tip load"),
                       ("gravity", "tip deflection, own weight"),
                       ("omega", "omega_1 (sparse eigen solve)")):
        print(f"| {label} | " + " | ".join(f"{100 * row[key]:+.3f} %" for row in rows.values())
              + " |")


if __name__ == "__main__":
    main()
