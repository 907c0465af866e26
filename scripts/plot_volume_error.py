#!/usr/bin/env python3
"""The 7x7 mass-spring test of Hong et al. (2006), with and without the area constraint.

Usage: python scripts/plot_volume_error.py [--reuse] [--in-process] [--out docs]

Runs cases/mass_spring_7x7.toml and cases/mass_spring_7x7_free.toml (through
``python -m parmps CASE -o out/<stem>``, or in this process with --in-process),
reads their result.h5 and draws

- docs/volume_error_7x7.png: the relative area error (V - V0)/V0 of both bodies
  over time (the seed's Figure 5), in percent and on a log scale;
- docs/squeeze_7x7.png: both bodies at the moment of largest squeeze (its Figure 4).

--reuse reads existing out/<stem>/result.h5 files instead of running the cases.
Prints the measured numbers.
"""

import argparse
import pathlib
import sys

import parmps
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
CASES = {"with constraint": ROOT / "cases" / "mass_spring_7x7.toml",
         "without constraint": ROOT / "cases" / "mass_spring_7x7_free.toml"}
COLOURS = {"with constraint": "tab:blue", "without constraint": "tab:red"}


def run_case(case, directory, in_process):
    if in_process:
        from mpi4py import MPI

        from parmps import config, schema
        from parmps.run.simulation import Simulation
        text = case.read_text()
        directory.mkdir(parents=True, exist_ok=True)
        Simulation(schema.validate(config.load_text(text)), text, MPI.COMM_WORLD,
                 str(directory)).execute()
        return
    from parmps.validation import launch
    record = launch.run(case, directory, timeout=None, root=ROOT, cwd=ROOT)
    if record["status"] != 0:
        sys.exit(f"{record['command']}: {record['outcome']}")


def read_result(directory):
    with parmps.open_result(directory) as result:
        (name,) = list(result.bodies)
        body = result.bodies[name]
        series = {key: body[key] for key in ("time", "volume_error", "centroid", "springs")}
        series["frames"] = {frame.time: frame.bodies[name]["position"]
                            for frame in result.frames}
        series["load"] = result.case["body"][0]["load"][0]
    return series


def plot_error(results, path):
    figure, (linear, logarithmic) = plt.subplots(2, 1, figsize=(6.4, 5.2), sharex=True)
    load = next(iter(results.values()))["load"]
    for axis in (linear, logarithmic):
        axis.axvspan(load["start"], load["end"], color="0.92", lw=0)
    for label, series in results.items():
        time = np.concatenate([[0.0], series["time"]])
        error = np.concatenate([[0.0], series["volume_error"]])
        linear.plot(time, 100 * error, color=COLOURS[label], lw=1.2, label=label)
        logarithmic.semilogy(time[1:], np.abs(error[1:]) + 1e-16, color=COLOURS[label],
                             lw=1.0, label=label)
    linear.set_ylabel("(V - V0)/V0 [%]")
    linear.legend(loc="lower right", fontsize=8)
    linear.set_title("7x7 mass-spring body pressed from above (grey), then released",
                     fontsize=10)
    logarithmic.set_ylabel("|V - V0|/V0")
    logarithmic.set_xlabel("time [s]")
    logarithmic.axhline(1e-6, color="0.4", ls=":", lw=0.8)
    logarithmic.set_ylim(1e-13, 1)
    figure.tight_layout()
    figure.savefig(path, dpi=80)
    plt.close(figure)


def plot_squeeze(results, path):
    free = results["without constraint"]
    frame_times = np.array(sorted(free["frames"]))
    # The frame nearest the free body's smallest area.
    worst = free["time"][np.argmin(free["volume_error"])]
    moment = frame_times[np.argmin(np.abs(frame_times - worst))]
    figure, axes = plt.subplots(1, 2, figsize=(6.4, 3.7), sharey=True)
    for axis, (label, series) in zip(axes, results.items()):
        rest = series["frames"][min(series["frames"])]
        position = series["frames"][moment]
        springs = series["springs"]
        axis.add_collection(LineCollection(rest[springs], colors="0.75", lw=0.6,
                                           linestyles="dashed"))
        axis.add_collection(LineCollection(position[springs], colors=COLOURS[label], lw=0.8))
        axis.plot(position[:, 0], position[:, 1], "o", color=COLOURS[label], ms=2.5)
        error = np.interp(moment, series["time"], series["volume_error"])
        axis.set_title(f"{label}\n(V - V0)/V0 = {error:.2e}", fontsize=9)
        axis.set_aspect("equal")
        axis.set_xlabel("x [m]")
        axis.margins(0.08)
    axes[0].set_ylabel("y [m]")
    figure.suptitle(f"largest squeeze, t = {moment:.3g} s (dashed: at rest)", fontsize=10)
    figure.tight_layout()
    figure.savefig(path, dpi=80)
    plt.close(figure)
    return moment


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--reuse", action="store_true", help="read existing results")
    parser.add_argument("--in-process", action="store_true",
                        help="run the cases in this process instead of python -m parmps")
    parser.add_argument("--out", default=str(ROOT / "docs"), help="where the PNGs go")
    args = parser.parse_args()
    results = {}
    for label, case in CASES.items():
        directory = ROOT / "out" / case.stem
        if not (args.reuse and (directory / "result.h5").exists()):
            run_case(case, directory, args.in_process)
        results[label] = read_result(directory)
    out = pathlib.Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    plot_error(results, out / "volume_error_7x7.png")
    moment = plot_squeeze(results, out / "squeeze_7x7.png")
    load = results["with constraint"]["load"]
    for label, series in results.items():
        loaded = (series["time"] >= load["start"]) & (series["time"] < load["end"])
        print(f"{label:>20}: max |V - V0|/V0 = {np.max(np.abs(series['volume_error'])):.3e} "
              f"(under load {np.max(np.abs(series['volume_error'][loaded])):.3e}), "
              f"final {series['volume_error'][-1]:.3e}")
    print(f"largest squeeze at t = {moment:.3g} s; figures in {out}/volume_error_7x7.png "
          f"and {out}/squeeze_7x7.png")


if __name__ == "__main__":
    main()
