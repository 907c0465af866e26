"""Velocity profiles of a plane Poiseuille run against the series solution at a few times.

    python validation/poiseuille_2d/plot.py OUT/result.h5 [PNG]
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from parmps.result import open_result  # noqa: E402
from parmps.tools.analysis import poiseuille_series  # noqa: E402


def main(path, png="poiseuille_2d.png"):
    with open_result(path) as result:
        case = result.case
        g, nu = case["physics"]["gravity"][0], case["fluid"]["viscosity"]
        lower, upper = case["tank"][0]["lower"][1], case["tank"][0]["upper"][1]
        height = upper - lower
        figure, axes = plt.subplots(figsize=(6, 4))
        frames = result.frames
        for frame in (frames[1], frames[2], frames[4], frames[-1]):
            fluid = frame.kind == 0
            y = frame.position[fluid, 1] - lower
            axes.plot(frame.velocity[fluid, 0] * 100, y * 100, ".", ms=2,
                      label=f"parmps, t = {frame.time:.2f} s")
            line = np.linspace(0.0, height, 200)
            axes.plot(poiseuille_series(line, frame.time, g, nu, height) * 100, line * 100,
                      "k-", lw=0.8)
        axes.set_xlabel("u [cm/s]")
        axes.set_ylabel("y above the floor [cm]")
        axes.set_title("plane Poiseuille start-up: parmps (dots), series (lines)")
        axes.legend(fontsize=7)
        figure.tight_layout()
        figure.savefig(png, dpi=120)
    print(png)


if __name__ == "__main__":
    main(*sys.argv[1:])
