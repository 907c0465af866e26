#!/usr/bin/env python3
"""The closed capsule shell pressed and released, with and without the volume constraint.

Usage: python validation/shell_squeeze_3d/plot.py [OUT] [--reuse]

Runs cases/shell_squeeze_3d.toml and cases/shell_squeeze_3d_free.toml into OUT/<stem>
(default out/), then draws docs/shell_squeeze_3d.png: |V - V0|/V0 over time (log scale)
and how far the top line of nodes sank, for both. --reuse reads results made before.
Prints the measured numbers.
"""

import logging
import pathlib
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

import parmps  # noqa: E402
from parmps.validation import launch  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[2]
CASES = {"with constraint": "shell_squeeze_3d", "without constraint": "shell_squeeze_3d_free"}
log = logging.getLogger("shell_squeeze_3d")


def series(directory):
    """(time, volume error, top-line sink per frame time) of the run in ``directory``."""
    with parmps.open_result(directory) as result:
        body = result.bodies["capsule"]
        time, error = np.asarray(body["time"]), np.asarray(body["volume_error"])
        frames = [(frame.time, frame.bodies["capsule"]["position"]) for frame in result.frames]
    start = frames[0][1]
    top = start[:, 2] >= start[:, 2].max() - 1e-9
    sink = np.array([[t, p[top, 2].mean() - start[top, 2].mean()] for t, p in frames])
    return time, error, sink


def main(argv):
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    out = pathlib.Path(next((a for a in argv if not a.startswith("--")), "out"))
    figure, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8))
    for label, stem in CASES.items():
        directory = out / stem
        if "--reuse" not in argv:
            record = launch.run(ROOT / "cases" / f"{stem}.toml", directory, timeout=None,
                                root=ROOT, cwd=ROOT)
            if record["status"] != 0:
                sys.exit(f"{record['command']}: {record['outcome']}")
        time, error, sink = series(directory)
        log.info("%s: max |V - V0|/V0 = %.3g, deepest sink of the top line %.2f mm", label,
                 np.abs(error).max(), -1e3 * sink[:, 1].min())
        left.semilogy(time, np.maximum(np.abs(error), 1e-17), label=label)
        right.plot(sink[:, 0], 1e3 * sink[:, 1], label=label)
    left.axvspan(0.0, 0.5, color="0.9", label="pressed")
    left.set(xlabel="t [s]", ylabel="|V - V0| / V0", title="enclosed volume")
    right.axvspan(0.0, 0.5, color="0.9")
    right.set(xlabel="t [s]", ylabel="top line z - z0 [mm]", title="top line of nodes")
    left.legend()
    figure.tight_layout()
    figure.savefig(ROOT / "docs" / "shell_squeeze_3d.png", dpi=110)


if __name__ == "__main__":
    main(sys.argv[1:])
