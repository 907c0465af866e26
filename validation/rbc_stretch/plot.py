#!/usr/bin/env python3
"""The red blood cell stretched through every force of Mills et al. (2004).

Usage: python validation/rbc_stretch/plot.py [RESULT] [--figure PATH]

Measures RESULT (a result file or output directory of validation/rbc_stretch/sweep.toml;
default out/validate/rbc_stretch, where ``python -m parmps validate rbc_stretch -n 1``
puts it) with the validation's metric, prints one line per force (diameters, the
experiment's range, speed and drift at the end of the hold, wall seconds) and draws
docs/rbc_stretch.png: both diameters against the force, over the experiment's band.
"""

import logging
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from parmps import validation  # noqa: E402
from parmps.result import result_path  # noqa: E402
from parmps.tools import analysis  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
log = logging.getLogger("rbc_stretch")


def main(argv):
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    args = [a for a in argv if not a.startswith("--")]
    figure_path = pathlib.Path(argv[argv.index("--figure") + 1]) if "--figure" in argv \
        else ROOT / "docs" / "rbc_stretch.png"
    if "--figure" in argv:
        args.remove(str(figure_path))
    path = result_path(args[0] if args else ROOT / "out" / "validate" / "rbc_stretch")
    check = validation.load("rbc_stretch")
    measured = check.measure(path)
    forces = list(measured["forces"].values())
    log.info("force_pN  axial_um (range)        transverse_um (range)   speed_m/s  drift_m  wall_s")
    for f in forces:
        log.info("%7.0f  %6.2f (%5.2f-%5.2f) %s  %6.2f (%5.2f-%5.2f) %s  %.1e  %.1e  %6.1f",
                 f["force_pN"], f["axial_um"], f["axial_low_um"], f["axial_high_um"],
                 " " if f["axial_in_range"] else "x", f["transverse_um"],
                 f["transverse_low_um"], f["transverse_high_um"],
                 " " if f["transverse_in_range"] else "x", f["speed"], f["drift"], f["wall"])
    log.info("outside the range: %d axial, %d transverse; area error %.1e, volume error %.1e; "
             "loop %.0f s", measured["axial_outside"], measured["transverse_outside"],
             measured["area_error"], measured["volume_error"], measured["wall"])
    table = analysis.reference_table(check.reference)
    axes = plt.subplots(figsize=(6, 4.2))[1]
    for name, colour in (("axial", "tab:blue"), ("transverse", "tab:red")):
        axes.fill_between(table["force_pN"], table[f"{name}_low_um"], table[f"{name}_high_um"],
                          color=colour, alpha=0.15, label=f"{name}, Mills et al. 2004 (range)")
        axes.plot([f["force_pN"] for f in forces], [f[f"{name}_um"] for f in forces], "o-",
                  color=colour, label=f"{name}, parmps")
    axes.set_xlabel("stretching force [pN]")
    axes.set_ylabel("diameter [µm]")
    axes.legend(fontsize=8)
    axes.grid(alpha=0.3)
    plt.tight_layout()
    plt.savefig(figure_path, dpi=120)
    log.info("wrote %s", figure_path)


if __name__ == "__main__":
    main(sys.argv[1:])
