#!/usr/bin/env python3
"""SPHERIC Test 2 (the 3D dam break against a box): a result against Kleefsman et al. (2005).

    python validation/dam_break_3d/plot.py OUT/result.h5 [--png docs/dam_break_3d.png]
                                          [--windows 0.1] [--section 0.6 0.8 1.0]

Run the case first, e.g. at 0.55/10 m on 2 ranks:

    ./scripts/run cases/dam_break_3d.toml --set particles.spacing=0.055 -o out/dam_break_3d_10

Prints, per sensor, the arrival (P1-P4), the means over the compared windows and the
peak of the 10 ms running mean, simulated beside measured, then the level gauges' wetting
and mean depths beside theirs; plots P1-P8 and H1-H4 over the record; with --windows,
each sensor's mean over short windows beside the record's; with --section, the flow
through the sensors' line at chosen times. Exits 1 when a target of validation.toml is
missed.
"""

import argparse
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(os.path.dirname(HERE)))


def judge(metrics, tolerance):
    """The targets missed, as sentences (empty: every target met)."""
    missed = []
    for name, row in sensors(metrics).items():
        if "arrival" in row and not abs(row["arrival_error"]) <= tolerance["arrival"]:
            missed.append(f"{name} arrival {row['arrival']:.3f} s against "
                          f"{row['arrival_measured']:.3f} s")
        limit = tolerance["front_mean"] if "arrival" in row else tolerance["top_mean"]
        for mean in row["means"]:
            if not abs(mean["error"]) <= limit:
                missed.append(f"{name} mean over {mean['window'][0]:g}-{mean['window'][1]:g} s "
                              f"{mean['error']:+.1%} (limit {limit:.0%})")
    return missed


def sensors(metrics):
    """The per-sensor rows of the metric (without the level gauges')."""
    return {name: row for name, row in metrics.items() if name != "levels"}


def level_lines(metrics):
    """The level gauges beside the record's: wetting time and mean depth per window."""
    lines = ["gauge  wet > 2 cm [s] (exp)  mean depth [m] sim / exp per window (reported, "
             "not judged)"]
    for name, row in metrics.get("levels", {}).items():
        means = "; ".join(f"{m['window'][0]:g}-{m['window'][1]:g}: {m['mean']:.3f} / "
                          f"{m['mean_measured']:.3f}" for m in row["means"])
        lines.append(f"{name:5}  {row['wet']:.3f} ({row['wet_measured']:.3f})        {means}")
    return lines


def table(metrics):
    lines = ["sensor  arrival [s] (exp)   means [Pa] sim / exp (error) per window      "
             "peak 10 ms [Pa] (exp) at t [s]"]
    for name, row in sensors(metrics).items():
        arrival = (f"{row['arrival']:.3f} ({row['arrival_measured']:.3f})"
                   if "arrival" in row else "-")
        means = "; ".join(f"{m['window'][0]:g}-{m['window'][1]:g}: {m['mean']:.0f} / "
                          f"{m['mean_measured']:.0f} ({m['error']:+.1%})" for m in row["means"])
        lines.append(f"{name:6}  {arrival:18}  {means:50}  {row['peak']:.0f} "
                     f"({row['peak_measured']:.0f}) at {row['peak_time']:.3f} "
                     f"({row['peak_time_measured']:.3f})")
    return "\n".join(lines + level_lines(metrics))


def windows(path, check, width, start=0.4):
    """Per sensor, the mean pressure over consecutive windows ``width`` long from ``start`` to
    the run's end, simulated / measured (a dry sample counts as 0 Pa, as in the metric), and
    the first time above 500 Pa of each: where in time a mean's error comes from."""
    import numpy as np

    from parmps.tools import analysis
    record = analysis.reference_table(check.reference)
    te = list(record.values())[0]
    rows = []
    for name in (f"P{i}" for i in range(1, 9)):
        t, p = analysis.read_probe(path, name)
        p = np.nan_to_num(p, nan=0.0)
        edges = np.arange(start, t[-1] - 0.5 * width + 1e-9, width)
        cells = " ".join(f"{analysis.window_mean(t, p, a, a + width):5.0f}/"
                         f"{analysis.window_mean(te, record[name], a, a + width):5.0f}"
                         for a in edges)
        wet = analysis.first_crossing(t, p, 500.0)
        wet_measured = analysis.first_crossing(te, record[name], 500.0)
        rows.append(f"{name}  first > 500 Pa {wet:.3f} ({wet_measured:.3f}) s  {cells}")
    head = (f"each sensor's first time above 500 Pa, simulated (measured), and its mean "
            f"pressure [Pa] simulated/measured over {width:g} s windows from {start:g} s")
    return "\n".join([head] + rows)


def section(path, times, png, half_width=None):
    """The tank's (x, z) section through the sensors' line (the pressure probes' y, 0.471 m
    in the case; one spacing thick), near the box, at the frames nearest ``times``: the fluid
    coloured by pressure with its velocity, the walls in black, the sensors P1-P8 marked."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from parmps.core.particles import FLUID
    from parmps.result import open_result
    with open_result(path) as result:
        spacing = result.case["particles"]["spacing"]
        half_width = 0.5 * spacing if half_width is None else half_width
        sensors = [probe["position"] for probe in result.case["probe"]
                   if probe["kind"] == "pressure"]
        y = sensors[0][1]
        figure, axes = plt.subplots(len(times), 1, figsize=(8, 2.6 * len(times)),
                                    squeeze=False)
        for ax, time in zip(axes[:, 0], times):
            frame = result.frames.nearest(time)
            x, kind = frame["position"], frame["kind"]
            near = (np.abs(x[:, 1] - y) <= half_width) & (x[:, 0] < 1.6) & (x[:, 2] < 0.8)
            fluid = near & (kind == FLUID)
            ax.scatter(x[near & (kind != FLUID), 0], x[near & (kind != FLUID), 2], s=2, c="k")
            shown = ax.scatter(x[fluid, 0], x[fluid, 2], s=5, c=frame["pressure"][fluid],
                               cmap="viridis", vmin=0.0, vmax=6000.0)
            v = frame["velocity"]
            ax.quiver(x[fluid, 0], x[fluid, 2], v[fluid, 0], v[fluid, 2], scale=100,
                      width=0.0012)
            for sensor in sensors:
                ax.plot(sensor[0], sensor[2], "r+", ms=8)
            ax.set_aspect("equal")
            ax.set_title(f"t = {frame.time:.2f} s, y = {y} m")
            figure.colorbar(shown, ax=ax, label="p [Pa]")
        figure.tight_layout()
        figure.savefig(png, dpi=90)
        plt.close(figure)


def plot(path, check, png):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from parmps.tools import analysis
    record = analysis.reference_table(check.reference)
    te = list(record.values())[0]
    figure, axes = plt.subplots(3, 4, figsize=(16, 10), sharex=True)
    for k, name in enumerate(f"P{i}" for i in range(1, 9)):
        ax = axes.flat[k]
        t, p = analysis.read_probe(path, name)
        ax.plot(te, record[name], color="0.6", lw=0.6, label="Kleefsman et al. (2005)")
        ax.plot(t, analysis.running_mean(t, p, 0.01), color="C0", lw=0.8,
                label="parmps, 10 ms mean")
        ax.set_title(name)
        ax.set_ylabel("p [Pa]")
    levels = analysis.reference_table(check.metric_arguments["level_reference"])
    for k, name in enumerate(f"H{i}" for i in range(1, 5)):
        ax = axes.flat[8 + k]
        t, level = analysis.read_probe(path, name)
        ax.plot(levels["t"], levels[name], color="0.6", lw=0.6)
        ax.plot(t, level, color="C1", lw=0.8)
        ax.set_title(f"{name} (water depth)")
        ax.set_ylabel("z [m]")
        ax.set_xlabel("t [s]")
    axes.flat[0].legend(fontsize=7)
    for ax in axes.flat:
        ax.set_xlim(0.0, 6.0)
    case = analysis.result_case(path)
    figure.suptitle(f"SPHERIC Test 2, l0 = {case['particles']['spacing'] * 1000:.1f} mm "
                    f"(0.55/{0.55 / case['particles']['spacing']:.0f} m)")
    figure.tight_layout()
    figure.savefig(png, dpi=110)
    plt.close(figure)


def main():
    from parmps import validation
    check = validation.load("dam_break_3d")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("result", help="result.h5 of cases/dam_break_3d.toml")
    parser.add_argument("--png", help="where to write the plot (default: none)")
    parser.add_argument("--windows", type=float, metavar="SECONDS",
                        help="also print each sensor's mean over windows this long, from "
                             "0.4 s on, beside the record's")
    parser.add_argument("--section", type=float, nargs="+", metavar="T",
                        help="draw the (x, z) section through the sensors at these times")
    parser.add_argument("--section-png", default="section.png",
                        help="where --section draws (default section.png)")
    args = parser.parse_args()
    if args.section:
        section(args.result, args.section, args.section_png)
        print(f"section: {args.section_png}")
    metrics = check.measure(args.result)
    print(table(metrics))
    if args.windows:
        print(windows(args.result, check, args.windows))
    if args.png:
        plot(args.result, check, args.png)
        print(f"plot: {args.png}")
    missed = judge(metrics, check.tolerance)
    for sentence in missed:
        print(f"missed: {sentence}")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
