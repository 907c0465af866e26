"""P1-P4 of SPHERIC Test 2 built from meshes beside the same scene built from boxes.

    python validation/dam_break_3d_meshed/plot.py MESHED/result.h5 BOXES/result.h5 [PNG]

(``python -m parmps validate dam_break_3d_meshed`` writes them to
out/validate/dam_break_3d_meshed/ and out/validate/dam_break_3d_meshed-boxes/.)
"""

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from parmps.tools.analysis import read_probe  # noqa: E402

PROBES = ("P1", "P2", "P3", "P4")


def main(meshed, boxes, png="dam_break_3d_meshed.png"):
    figure, axes = plt.subplots(len(PROBES), 1, figsize=(7, 8), sharex=True)
    for axis, name in zip(axes, PROBES):
        for path, style, label in ((boxes, "k-", "boxes"), (meshed, "r--", "meshes")):
            t, p = read_probe(path, name)
            axis.plot(t, p / 1000.0, style, lw=0.8, label=label)
        axis.set_ylabel(f"{name} [kPa]")
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("t [s]")
    figure.suptitle("SPHERIC Test 2: the scene from meshes and from boxes")
    figure.tight_layout()
    figure.savefig(png, dpi=120)
    print(png)


if __name__ == "__main__":
    main(*sys.argv[1:])
