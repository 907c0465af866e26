#!/usr/bin/env python3
"""The plate's centre deflection over time beside Kirchhoff's static answer, from a run of
cases/hydrostatic_plate_3d.toml.

    mpirun -n 2 python -m parmps cases/hydrostatic_plate_3d.toml -o out
    python validation/hydrostatic_plate_3d/plot.py out/result.h5 [--png docs/hydrostatic_plate_3d.png]

Prints the metric (validation.toml) and plots the series, its mean over the whole periods of
the averaging window and Kirchhoff's 0.00126 q a^4 / D with the 5 % band.
"""

import argparse

from parmps import validation


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("result")
    parser.add_argument("--png", default=None)
    args = parser.parse_args()
    check = validation.load("hydrostatic_plate_3d")
    measured = check.measure(args.result)
    print(f"centre deflection {measured['deflection']:.4e} m against Kirchhoff "
          f"{measured['expected']:.4e} m: {100 * measured['error']:+.2f} % "
          f"(mean over {measured['periods']} periods of {measured['period']:.4f} s; half the "
          f"range after {check.metric['settle_time']} s: {measured['amplitude']:.2e} m)")
    if args.png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        expected, settle = 1e3 * measured["expected"], check.metric["settle_time"]
        fig, ax = plt.subplots(figsize=(6.0, 3.4))
        ax.plot(measured["time"], 1e3 * measured["series"], lw=1.0, label="parmps, centre")
        ax.axhspan(0.95 * expected, 1.05 * expected, color="gray", alpha=0.2, label="± 5 %")
        ax.axhline(expected, color="k", lw=0.8, label="Kirchhoff, 0.00126 q a$^4$/D")
        end = measured["time"][-1]
        start = end - measured["periods"] * measured["period"] if measured["periods"] else settle
        ax.hlines(1e3 * measured["deflection"], start, end, colors="C3", lw=2,
                  label=f"mean over {measured['periods']} whole periods: "
                        f"{100 * measured['error']:+.1f} %")
        ax.set_xlabel("t [s]")
        ax.set_ylabel("centre deflection [mm]")
        ax.legend(fontsize=8, loc="upper right")
        fig.tight_layout()
        fig.savefig(args.png, dpi=110)


if __name__ == "__main__":
    main()
