"""Point A's displacement in a Turek & Hron CSM3 run, with the benchmark's mean +- amplitude.

    python validation/turek_hron_csm3/plot.py OUT/result.h5 [PNG]
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from parmps.result import open_result  # noqa: E402

# Turek & Hron (2006), CSM3: mean and amplitude of A's displacement [mm].
REFERENCE = {"x": (-14.305, 14.305), "y": (-63.607, 65.160)}


def main(path, png="turek_hron_csm3.png"):
    with open_result(path) as result:
        series = result.probes["A"]
        time, value = np.asarray(series["time"]), np.asarray(series["value"]) * 1000.0
    figure, axes = plt.subplots(2, 1, figsize=(7, 5), sharex=True)
    for k, axis in enumerate("xy"):
        mean, amplitude = REFERENCE[axis]
        axes[k].plot(time, value[:, k], "b-", lw=0.8, label="parmps")
        for level in (mean - amplitude, mean + amplitude):
            axes[k].axhline(level, color="k", ls="--", lw=0.7)
        axes[k].set_ylabel(f"u_{axis}(A) [mm]")
    axes[0].legend(["parmps", "Turek & Hron: mean ± amplitude"], fontsize=8)
    axes[1].set_xlabel("t [s]")
    figure.suptitle("CSM3: the flag released under gravity 2 m/s²")
    figure.tight_layout()
    figure.savefig(png, dpi=120)
    print(png)


if __name__ == "__main__":
    main(*sys.argv[1:])
