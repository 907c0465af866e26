#!/usr/bin/env python3
"""Plot the elastic gate's free-end displacement and snapshots of a run of cases/elastic_gate.toml.

    scripts/plot_elastic_gate.py OUT [--png docs/elastic_gate.png]

OUT is the run's output directory (or its result.h5). The upper panel is the free end's
horizontal and vertical displacement (the displacement probe, every step; the
validation's metric, validation/elastic_gate/), with the crossings of the gate counted
every step, beside the experiment's points (the validation's references: Antoci et al.'s
measured free-end displacement); the lower row shows the particles at four times.
"""

import argparse
import os
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from parmps import validation
from parmps.core.particles import FLUID, SOLID
from parmps.tools import analysis


def frames_near(path, times):
    """(time, fluid positions, node positions) of the frame nearest each of ``times``."""
    import parmps
    out = []
    with parmps.open_result(path) as result:
        for t in times:
            frame = result.frames.nearest(t)
            kind, position = frame.kind, frame.position
            out.append((frame.time, position[kind == FLUID], position[kind == SOLID],
                        position[(kind != FLUID) & (kind != SOLID)]))
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", help="the run's output directory or its result.h5")
    parser.add_argument("--png", default=os.path.join(ROOT, "docs", "elastic_gate.png"))
    args = parser.parse_args()

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from parmps.result import result_path
    path = result_path(args.output)
    check = validation.load("elastic_gate")
    measured = check.measure(path)
    case = analysis.result_case(path)

    figure = plt.figure(figsize=(10, 5.6), dpi=110)
    grid = figure.add_gridspec(2, 4, height_ratios=(1.6, 0.8))
    ax = figure.add_subplot(grid[0, :])
    ax.plot(measured["time"], 1e3 * measured["dx"], color="C0",
            label="horizontal (parmps)")
    ax.plot(measured["time"], 1e3 * measured["dy"], color="C1", label="vertical (parmps)")
    references = check.metric_arguments.get("references", {})
    for component, color, marker in (("dx", "C0", "o"), ("dy", "C1", "s")):
        if component in references:
            t_ref, v_ref = list(analysis.reference_table(references[component]).values())[:2]
            ax.plot(t_ref, 1e3 * v_ref, marker, color=color, ms=4,
                    label=("horizontal" if component == "dx" else "vertical")
                    + " (experiment, Antoci et al. 2007)")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("free-end displacement [mm]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left")
    spacing = case["particles"]["spacing"]
    ax.set_title(f"elastic gate (Antoci et al. 2007 set-up), l0 = {1e3 * spacing:.3g} mm: "
                 f"max dx = {1e3 * measured['dx_max']:.1f} mm at t = "
                 f"{measured['t_dx_max']:.3f} s; fluid crossings {measured['crossings']}, "
                 f"max area error {measured['volume_error']:.1e}\nagainst the experiment: peak "
                 f"{100 * measured.get('dx_peak_error', np.nan):+.0f} %, RMS "
                 f"{100 * measured.get('dx_rms_error', np.nan):.0f} % of its peak", fontsize=9)
    end = measured["end"]
    for k, (t, fluid, nodes, walls) in enumerate(frames_near(path, np.linspace(0.1, 1.0, 4)
                                                             * end)):
        panel = figure.add_subplot(grid[1, k])
        panel.scatter(walls[:, 0], walls[:, 1], s=0.3, c="0.6", lw=0)
        panel.scatter(fluid[:, 0], fluid[:, 1], s=0.3, c="C0", lw=0)
        panel.scatter(nodes[:, 0], nodes[:, 1], s=1.0, c="C3", lw=0)
        panel.set_xlim(-0.01, 0.3)
        panel.set_ylim(-0.01, 0.16)
        panel.set_aspect("equal")
        panel.set_title(f"t = {t:.3f} s", fontsize=8)
        panel.tick_params(labelsize=6)
    figure.text(0.01, 0.005, f"python scripts/plot_elastic_gate.py OUT after "
                f"mpirun -n 2 python -m parmps cases/elastic_gate.toml -o OUT",
                fontsize=6, color="0.4")
    figure.tight_layout(rect=(0, 0.02, 1, 1))
    figure.savefig(args.png)
    print(f"{args.png}: dx_max {measured['dx_max']:.4g} m at t = {measured['t_dx_max']:.4g} s, "
          f"dy_max {measured['dy_max']:.4g} m, crossings {measured['crossings']}, "
          f"area error {measured['volume_error']:.3g}, end {measured['end']:.4g} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
