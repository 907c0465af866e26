#!/usr/bin/env python3
"""The 3D elastic gate's free end beside 2D runs and the experiment, from a run of
cases/elastic_gate_3d.toml.

    mpirun -n 2 python -m parmps cases/elastic_gate_3d.toml -o out/gate3d
    python validation/elastic_gate_3d/plot.py out/gate3d \
        [--beside "2D, plane strain=out/gate2d_strain" ...] [--png docs/elastic_gate_3d.png]

Prints the metric (validation.toml) of the 3D run and of every --beside run (any run with the
same probe and check, for example the 2D case at the 3D lattice, README.md), and plots the
free end's horizontal and vertical displacement of each beside the experiment's points; the
lower row shows the particles within one spacing of the tank's mid-width at four times.
"""

import argparse
import sys

import numpy as np

from parmps import validation
from parmps.core.particles import FLUID, SOLID
from parmps.result import result_path
from parmps.tools import analysis


def mid_width_slices(path, times):
    """(time, [fluid, nodes, walls] x-z positions within one spacing of the mid-width)."""
    import parmps
    spacing = analysis.result_case(path)["particles"]["spacing"]
    out = []
    with parmps.open_result(path) as result:
        for t in times:
            frame = result.frames.nearest(t)
            kind, position = frame.kind, frame.position
            near = np.abs(position[:, 1] - 0.05) < spacing
            groups = [(kind == FLUID), (kind == SOLID), (kind != FLUID) & (kind != SOLID)]
            out.append((frame.time, [position[near & g][:, [0, 2]] for g in groups]))
    return out


def describe(label, measured):
    return (f"{label}: peak dx {1e3 * measured['dx_max']:.1f} mm at t = "
            f"{measured['t_dx_max']:.3f} s ({100 * measured['dx_peak_error']:+.1f} %), RMS "
            f"{100 * measured['dx_rms_error']:.1f} %; rise {1e3 * measured['dy_max']:.1f} mm "
            f"({100 * measured['dy_peak_error']:+.1f} %); crossings {measured['crossings']}, "
            f"volume error {measured['volume_error']:.1e}, end {measured['end']:.3f} s")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", help="the 3D run's output directory or its result.h5")
    parser.add_argument("--beside", action="append", default=[], metavar="LABEL=OUT",
                        help="another run of the gate to plot beside it")
    parser.add_argument("--png", default=None)
    args = parser.parse_args()
    check = validation.load("elastic_gate_3d")
    path = result_path(args.output)
    runs = [("3D", check.measure(path))]
    for item in args.beside:
        label, _, other = item.partition("=")
        runs.append((label, check.measure(result_path(other))))
    for label, measured in runs:
        print(describe(label, measured))
    if not args.png:
        return 0

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figure = plt.figure(figsize=(10, 6.0), dpi=110)
    grid = figure.add_gridspec(2, 4, height_ratios=(1.6, 0.8))
    ax = figure.add_subplot(grid[0, :])
    styles = ["-", "--", ":", "-."]
    for k, (label, measured) in enumerate(runs):
        style = styles[k % len(styles)]
        width = 1.6 if k == 0 else 1.0
        ax.plot(measured["time"], 1e3 * measured["dx"], style, color="C0", lw=width,
                label=f"horizontal, {label}")
        ax.plot(measured["time"], 1e3 * measured["dy"], style, color="C1", lw=width,
                label=f"vertical, {label}")
    references = check.metric_arguments["references"]
    top = max(1e3 * measured["dx"].max() for _, measured in runs)
    for component, color, marker in (("dx", "C0", "o"), ("dy", "C1", "s")):
        t_ref, v_ref = list(analysis.reference_table(references[component]).values())[:2]
        top = max(top, 1e3 * float(np.max(v_ref)))
        ax.plot(t_ref, 1e3 * v_ref, marker, color=color, ms=4,
                label=("horizontal" if component == "dx" else "vertical")
                + ", experiment (Antoci et al. 2007)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("free-end displacement [mm]")
    ax.grid(alpha=0.3)
    ax.set_ylim(-2.0, 1.45 * top)  # room for the legend above the curves
    ax.legend(fontsize=7, loc="upper left", ncol=2)
    measured = runs[0][1]
    ax.set_title(f"elastic gate in 3D, 0.1 m wide, l0 = 2.5 mm, free end at mid-width: peak "
                 f"{1e3 * measured['dx_max']:.1f} mm at t = {measured['t_dx_max']:.3f} s "
                 f"({100 * measured['dx_peak_error']:+.0f} % against the experiment, RMS "
                 f"{100 * measured['dx_rms_error']:.0f} %)", fontsize=9)
    end = measured["end"]
    for k, (t, (fluid, nodes, walls)) in enumerate(
            mid_width_slices(path, np.linspace(0.1, 1.0, 4) * end)):
        panel = figure.add_subplot(grid[1, k])
        panel.scatter(walls[:, 0], walls[:, 1], s=0.3, c="0.6", lw=0)
        panel.scatter(fluid[:, 0], fluid[:, 1], s=0.3, c="C0", lw=0)
        panel.scatter(nodes[:, 0], nodes[:, 1], s=1.0, c="C3", lw=0)
        panel.set_xlim(-0.01, 0.51)
        panel.set_ylim(-0.01, 0.21)
        panel.set_aspect("equal")
        panel.set_title(f"t = {t:.3f} s, mid-width", fontsize=8)
        panel.tick_params(labelsize=6)
    figure.text(0.01, 0.005, "python validation/elastic_gate_3d/plot.py OUT --beside ... after "
                "mpirun -n 2 python -m parmps cases/elastic_gate_3d.toml -o OUT",
                fontsize=6, color="0.4")
    figure.tight_layout(rect=(0, 0.02, 1, 1))
    figure.savefig(args.png)
    print(f"wrote {args.png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
