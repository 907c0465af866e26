#!/usr/bin/env python3
"""The fluid-filled capsule carried by the 3D duct flow.

Usage: python validation/capsule_3d/plot.py [OUT] [--reuse] [-n RANKS]

Runs cases/capsule_3d.toml into OUT/capsule_3d (default out/, 2 ranks), then draws
docs/capsule_3d.png: the duct's middle plane (y = 0.065 m, a slice one spacing thick) at
the start, halfway and at the end, the water coloured by its pressure and the shell's nodes
in red; and over time the capsule's travel against U0 t and the developed duct flow's
centreline 2.096 U0 t, and its volume error. --reuse reads a result made before. Prints the
measured numbers.
"""

import logging
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import parmps  # noqa: E402
from parmps.core.particles import FLUID, SOLID  # noqa: E402
from parmps.validation import launch  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
U0 = 0.1          # the inflow's speed [m/s]
CENTRELINE = 2.096  # a square duct's developed centreline speed over its mean
MIDDLE, SLICE = 0.065, 0.006  # the duct's middle plane y and the slice's half-width [m]
log = logging.getLogger("capsule_3d")


def sections(result, axes):
    """The middle plane at the first, middle and last frame, one per axis."""
    frames = result.frames
    for axis, k in zip(axes, (0, len(frames) // 2, len(frames) - 1)):
        frame = frames[k]
        position, kind = frame["position"], frame["kind"]
        near = np.abs(position[:, 1] - MIDDLE) < SLICE
        water = near & (kind == FLUID)
        shown = axis.scatter(position[water, 0], position[water, 2], s=5,
                             c=frame["pressure"][water], cmap="viridis")
        shell = near & (kind == SOLID)
        axis.scatter(position[shell, 0], position[shell, 2], s=14, c="tab:red")
        axis.set(aspect="equal", xlim=(0.0, 0.40), ylim=(0.0, 0.13), xlabel="x [m]",
                 title=f"t = {frame.time:.2f} s")
    axes[0].set_ylabel("z [m]")
    return shown


def main(argv):
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = pathlib.Path(next((a for a in argv if not a.startswith("-") and not a.isdigit()),
                            "out")) / "capsule_3d"
    ranks = int(argv[argv.index("-n") + 1]) if "-n" in argv else 2
    if "--reuse" not in argv:
        record = launch.run(ROOT / "cases" / "capsule_3d.toml", out, ranks=ranks,
                            timeout=None, root=ROOT, cwd=ROOT)
        if record["status"] != 0:
            sys.exit(f"{record['command']}: {record['outcome']}")
    figure = plt.figure(figsize=(15, 6))
    grid = figure.add_gridspec(2, 3)
    with parmps.open_result(out) as result:
        shown = sections(result, [figure.add_subplot(grid[0, k]) for k in range(3)])
        body = result.bodies["capsule"]
        time = np.asarray(body["time"])
        centroid = np.asarray(body["centroid"])
        error = np.abs(np.asarray(body["volume_error"]))
        inside = np.asarray(body["fluid_inside"])
        crossings = int(result.checks["body_crossing_capsule"]["total"][-1])
    figure.colorbar(shown, ax=figure.axes[:3], label="pressure [Pa]", shrink=0.8)
    travel = centroid[0, 0] - centroid[:, 0]
    log.info("carried %.4f m in %.3g s (%.3f U0 on average); largest |V - V0|/V0 %.2g; "
             "water inside %d to %d particles; %d crossings", travel[-1], time[-1],
             travel[-1] / (U0 * time[-1]), error.max(), inside.min(), inside.max(), crossings)
    carried = figure.add_subplot(grid[1, 0:2])
    carried.plot(time, 100 * travel, label="capsule's centroid")
    carried.plot(time, 100 * U0 * time, "k--", label="U0 t (the duct's mean)")
    carried.plot(time, 100 * CENTRELINE * U0 * time, "k:",
                 label="2.096 U0 t (developed centreline)")
    carried.set(xlabel="t [s]", ylabel="travel along the flow [cm]", title="carried")
    carried.legend()
    volume = figure.add_subplot(grid[1, 2])
    volume.semilogy(time, np.maximum(error, 1e-17))
    volume.set(xlabel="t [s]", ylabel="|V - V0| / V0", title="enclosed volume")
    figure.savefig(ROOT / "docs" / "capsule_3d.png", dpi=100, bbox_inches="tight")


if __name__ == "__main__":
    main(sys.argv[1:])
