"""The centre-line velocity of a Womersley run against the analytic solution.

    python validation/womersley_3d/plot.py OUT/result.h5 [PNG]
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from parmps.result import open_result  # noqa: E402
from parmps.tools.analysis import womersley_velocity  # noqa: E402


def main(path, png="womersley_3d.png"):
    with open_result(path) as result:
        case = result.case
        physics, nu = case["physics"], case["fluid"]["viscosity"]
        amplitude, frequency = physics["gravity_amplitude"][0], physics["gravity_frequency"]
        spacing = case["particles"]["spacing"]
        times, centre, exact = [], [], []
        for frame in result.frames:
            fluid = frame.kind == 0
            r = np.hypot(frame.position[fluid, 1], frame.position[fluid, 2])
            near = r < 1.5 * spacing
            times.append(frame.time)
            centre.append(frame.velocity[fluid, 0][near].mean())
            exact.append(womersley_velocity(r[near], frame.time, amplitude, frequency, nu,
                                            0.008).mean())
    figure, axes = plt.subplots(figsize=(7, 3.5))
    axes.plot(np.asarray(times) * 1000, np.asarray(centre) * 100, "b.", ms=3, label="parmps")
    axes.plot(np.asarray(times) * 1000, np.asarray(exact) * 100, "k-", lw=0.8,
              label="Womersley (periodic state)")
    axes.set_xlabel("t [ms]")
    axes.set_ylabel("centre-line u [cm/s]")
    axes.set_title("Womersley flow, alpha = 4: the start-up, then the periodic state")
    axes.legend(fontsize=8)
    figure.tight_layout()
    figure.savefig(png, dpi=120)
    print(png)


if __name__ == "__main__":
    main(*sys.argv[1:])
