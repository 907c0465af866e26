#!/usr/bin/env python3
"""The 3D cantilever's dynamic run: its tip deflection beside Euler-Bernoulli's.

    python -m parmps cases/elastic_cantilever_3d.toml -o out/elastic_cantilever_3d
    python validation/cantilever_3d/plot.py out/elastic_cantilever_3d/result.h5 \\
        [--png docs/cantilever_3d.png]

Prints the period of the tip's swing against 2 pi/omega_1 (the metric of validation.toml)
and plots the tip deflection with the undamped first mode of the same period,
w_s (1 - cos omega_1 t), w_s = P L^3/3EI; exits 1 when the period misses the tolerance.
"""

import argparse
import math
import sys

from parmps import validation
from parmps.tools import analysis


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("result")
    parser.add_argument("--png", default=None)
    args = parser.parse_args()
    check = validation.load("cantilever_3d")
    measured = check.measure(args.result)
    print(f"period {measured['period']:.5f} s, Euler-Bernoulli {measured['expected']:.5f} s, "
          f"error {100 * measured['error']:+.3f} %; mean deflection "
          f"{1e3 * measured['mean_deflection']:.4f} mm")
    if args.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import numpy as np
        case = analysis.result_case(args.result)
        (spec,) = case["body"]
        (load,) = spec["load"]
        length, depth = (spec["nx"] - 1) * spec["spacing"], (spec["nz"] - 1) * spec["spacing"]
        width = (spec["ny"] - 1) * spec["spacing"]
        tip_load = load["force"][2] * spec["ny"] * spec["nz"]
        static = tip_load * length ** 3 / (3 * spec["youngs_modulus"] * width * depth ** 3 / 12)
        t = measured["time"]
        omega = 2 * math.pi / measured["expected"]
        fig, ax = plt.subplots(figsize=(7, 3.2))
        ax.plot(t, 1e3 * measured["series"], label="lattice, 4 x 4 nodes across (time integrator)")
        ax.plot(t, 1e3 * static * (1 - np.cos(omega * t)), "--",
                label="Euler-Bernoulli: $w_s (1 - \\cos \\omega_1 t)$")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("tip deflection [mm]")
        ax.set_ylim(1e3 * min(2 * static, 0) * 1.05, 1e3 * abs(static) * 0.6)
        ax.legend(loc="upper center", ncol=2, fontsize=8)
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)
    return 0 if abs(measured["error"]) <= check.tolerance["period"] else 1


if __name__ == "__main__":
    sys.exit(main())
