"""The drag and lift coefficients and the front-back pressure difference of a Schäfer & Turek
2D-1 run, beside the benchmark's intervals.

    python validation/schaefer_turek_2d1/plot.py OUT/result.h5 [PNG]
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from parmps.tools import analysis  # noqa: E402

# Schäfer & Turek (1996), 2D-1: the organisers' intervals for C_D, C_L and delta p [Pa / rho].
REFERENCE = {"C_D": (5.57, 5.59), "C_L": (0.0104, 0.0110), "Δp/ρ [m²/s²]": (0.1172, 0.1176)}
DENSITY, MEAN_VELOCITY, DIAMETER = 1000.0, 0.2, 0.1  # cases/schaefer_turek_2d1.toml
WIDTH = 0.5  # [s] the running mean's window


def main(path, png="schaefer_turek_2d1.png"):
    t, force = analysis.read_probe(path, "cylinder")
    scale = 0.5 * DENSITY * MEAN_VELOCITY ** 2 * DIAMETER
    tf, front = analysis.read_probe(path, "front")
    tb, back = analysis.read_probe(path, "back")
    series = {"C_D": (t, force[:, 0] / scale), "C_L": (t, force[:, 1] / scale),
              "Δp/ρ [m²/s²]": (tf, (front - np.interp(tf, tb, back)) / DENSITY)}
    figure, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    for axis, (name, (time, value)) in zip(axes, series.items()):
        axis.plot(time, value, color="0.8", lw=0.3, label="every step")
        axis.plot(time, analysis.running_mean(time, value, WIDTH), "b-", lw=1.0,
                  label=f"running mean over {WIDTH:g} s")
        low, high = REFERENCE[name]
        axis.axhspan(low, high, color="k", alpha=0.4, label="Schäfer & Turek")
        middle = 0.5 * (low + high)
        axis.set_ylim(middle - 1.0 * max(abs(middle), 0.05), middle + 1.0 * max(abs(middle), 0.05))
        axis.set_ylabel(name)
    axes[0].legend(fontsize=8, loc="lower right")
    axes[-1].set_xlabel("t [s]")
    figure.suptitle("Schäfer & Turek 2D-1 (Re 20): the cylinder's drag, lift and Δp")
    figure.tight_layout()
    figure.savefig(png, dpi=120)
    print(png)


if __name__ == "__main__":
    main(*sys.argv[1:])
