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
import sys


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
    """The per-sensor rows of the metric (without the level gauges' or the origin)."""
    return {name: row for name, row in metrics.items()
            if name != "levels" and isinstance(row, dict)}


def level_lines(metrics):
    """The level gauges beside the record's: wetting time and mean depth per window (the
    record on the shifted clock, its own clock's in brackets)."""
    lines = ["gauge  wet > 2 cm [s] (exp; exp raw)  mean depth [m] sim / exp (exp raw) per "
             "window (reported, not judged)"]
    for name, row in metrics.get("levels", {}).items():
        means = "; ".join(f"{m['window'][0]:g}-{m['window'][1]:g}: {m['mean']:.3f} / "
                          f"{m['mean_measured']:.3f} ({m['mean_measured_raw']:.3f})"
                          for m in row["means"])
        lines.append(f"{name:5}  {row['wet']:.3f} ({row['wet_measured']:.3f}; "
                     f"{row['wet_measured_raw']:.3f})  {means}")
    return lines


def table(metrics):
    """The metric as a table: each figure of the record on the clock shifted by the
    record's origin, the record's own clock's beside it ("raw")."""
    origin = metrics.get("record_origin_ms", 0.0)
    lines = [f"record's origin: {origin:.0f} ms (the record's t = 0 is {origin:.0f} ms after "
             f"the release; judged on that clock, raw = the record's own clock)",
             "sensor  arrival [s] sim (exp; exp raw) error [ms] (raw)   means [Pa] sim / exp "
             "(error; raw error) per window   peak 10 ms [Pa] (exp) at t [s] (exp)"]
    for name, row in sensors(metrics).items():
        arrival = (f"{row['arrival']:.3f} ({row['arrival_measured']:.3f}; "
                   f"{row['arrival_measured_raw']:.3f}) {1000 * row['arrival_error']:+.0f} "
                   f"({1000 * row['arrival_error_raw']:+.0f})" if "arrival" in row else "-")
        means = "; ".join(f"{m['window'][0]:g}-{m['window'][1]:g}: {m['mean']:.0f} / "
                          f"{m['mean_measured']:.0f} ({m['error']:+.1%}; {m['error_raw']:+.1%})"
                          for m in row["means"])
        lines.append(f"{name:6}  {arrival:36}  {means:66}  {row['peak']:.0f} "
                     f"({row['peak_measured']:.0f}) at {row['peak_time']:.3f} "
                     f"({row['peak_time_measured']:.3f})")
    return "\n".join(lines + level_lines(metrics))


def windows(path, check, width, start=0.4):
    """Per sensor, the mean pressure over consecutive windows ``width`` long from ``start`` to
    the run's end, simulated / measured (a dry sample counts as 0 Pa, as in the metric), and
    the first time above 500 Pa of each: where in time a mean's error comes from. The record
    on the clock shifted by its origin (``[metric] record_origin``), as the metric reads it."""
    import numpy as np

    from parmps.tools import analysis
    record = analysis.reference_table(check.reference)
    te = list(record.values())[0] + check.metric_arguments.get("record_origin", 0.0)
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
            f"pressure [Pa] simulated/measured over {width:g} s windows from {start:g} s "
            f"(the record's clock shifted by its origin)")
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
    origin = check.metric_arguments.get("record_origin", 0.0)
    figure, axes = plt.subplots(3, 4, figsize=(16, 10), sharex=True)
    for k, name in enumerate(f"P{i}" for i in range(1, 9)):
        ax = axes.flat[k]
        t, p = analysis.read_probe(path, name)
        ax.plot(te, record[name], color="0.75", lw=0.5,
                label="Kleefsman et al. (2005), its own clock")
        ax.plot(te + origin, record[name], color="0.3", lw=0.5,
                label=f"the same, {1000 * origin:.0f} ms later (judged)")
        ax.plot(t, analysis.running_mean(t, p, 0.01), color="C0", lw=0.8,
                label="parmps, 10 ms mean")
        ax.set_title(name)
        ax.set_ylabel("p [Pa]")
    levels = analysis.reference_table(check.metric_arguments["level_reference"])
    for k, name in enumerate(f"H{i}" for i in range(1, 5)):
        ax = axes.flat[8 + k]
        t, level = analysis.read_probe(path, name)
        ax.plot(levels["t"], levels[name], color="0.75", lw=0.5)
        ax.plot(levels["t"] + origin, levels[name], color="0.3", lw=0.5)
        ax.plot(t, level, color="C1", lw=0.8)
        ax.set_title(f"{name} (water depth)")
        ax.set_ylabel("z [m]")
        ax.set_xlabel("t [s]")
    axes.flat[0].legend(fontsize=7)
    end = min(6.0, float(analysis.read_probe(path, "P1")[0][-1]))  # a short run: its own span
    for ax in axes.flat:
        ax.set_xlim(0.0, end)
    case = analysis.result_case(path)
    figure.suptitle(f"SPHERIC Test 2, l0 = {case['particles']['spacing'] * 1000:.1f} mm "
                    f"(0.55/{0.55 / case['particles']['spacing']:.0f} m)")
    figure.tight_layout()
    figure.savefig(png, dpi=110)
    plt.close(figure)


ORIGIN_WINDOWS = ((0.0, 0.2), (0.0, 0.25), (0.0, 0.3), (0.0, 0.35))
THEORY_WINDOWS = ((0.0, 0.03), (0.0, 0.05), (0.0, 0.07))


def origin(paths, check, png=None):
    """The record's clock against an instant release, from its reservoir gauge H4 (and H3):
    per result, the delay fitted over each of ORIGIN_WINDOWS (the record's gauge reading the
    0.55 m at rest; then with its baseline fitted too), H3's wetting beside the record's;
    then against the incompressible start over THEORY_WINDOWS. With ``png``, the record's
    H4 on both clocks over the runs' and the incompressible start's."""
    import numpy as np

    from parmps.tools import analysis
    record = analysis.reference_table(check.metric_arguments["level_reference"])
    lines = ["origin of the record's clock [ms] (its t = 0 after an instant release), from H4 "
             "over record windows 0-T s: delay +- standard error (rms residual [mm])"]
    for path in paths:
        case = analysis.result_case(path)
        names = [probe["name"] for probe in case["probe"] if probe["kind"] == "level"]
        cells = []
        for window in ORIGIN_WINDOWS:
            fit = analysis.record_origin_fits(record, [path], ("H4",), window)[0]
            cells.append(f"0-{window[1]:g}: {1000 * fit['delay']:.1f} +- "
                         f"{1000 * fit['stderr']:.1f} ({1000 * fit['rms']:.1f})")
        t, level = analysis.read_probe(path, "H4")
        free = analysis.record_delay(record["t"], record["H4"], t, level, ORIGIN_WINDOWS[-1])
        cells.append(f"baseline fitted, 0-{ORIGIN_WINDOWS[-1][1]:g}: "
                     f"{1000 * free['delay']:.1f} +- {1000 * free['stderr']:.1f} "
                     f"(gauge {1000 * (free['baseline'] - 0.55 + level[0]):+.1f} mm)")
        spacing = case["particles"]["spacing"]
        lines.append(f"{case.get('title', '')[:18]:18} l0 = 0.55/{0.55 / spacing:.0f} m: "
                     + "; ".join(cells))
        if "H3" in names:
            t3, h3 = analysis.read_probe(path, "H3")
            wet = analysis.first_crossing(t3, np.ravel(h3), 0.02)
            wet_e = analysis.first_crossing(record["t"], record["H3"], 0.02)
            lines.append(f"{'':18} H3 deeper than 2 cm at {wet:.3f} s, the record at "
                         f"{wet_e:.3f} s: {1000 * (wet - wet_e):+.0f} ms (the front's, not "
                         f"the clock's)")
    # The geometry as published: the validated case has its faces snapped to a lattice.
    case = dict(check.case(), fluid_block=check.raw_case()["fluid_block"])
    cells = []
    for window in THEORY_WINDOWS:
        fit = analysis.record_origin_fits(record, (), ("H4",), theory_window=window,
                                          case=case)[0]
        cells.append(f"0-{window[1]:g}: {1000 * fit['delay']:.1f} +- {1000 * fit['stderr']:.1f} "
                     f"({1000 * fit['rms']:.1f})")
    lines.append(f"incompressible start (a = {fit['acceleration'] / 9.81:.4f} g at H4): "
                 + "; ".join(cells))
    chosen = check.metric_arguments.get("record_origin", 0.0)
    lines.append(f"judged with [metric] record_origin = {1000 * chosen:.0f} ms")
    if png:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        figure, ax = plt.subplots(1, 1, figsize=(8, 5))
        ax.plot(record["t"], record["H4"], ".", color="0.7", ms=3,
                label="record H4, its own clock")
        ax.plot(record["t"] + chosen, record["H4"], ".", color="0.2", ms=3,
                label=f"record H4, {1000 * chosen:.0f} ms later")
        for k, path in enumerate(paths):
            t, level = analysis.read_probe(path, "H4")
            level = np.ravel(level)
            spacing = analysis.result_case(path)["particles"]["spacing"]
            dims = len(analysis.result_case(path)["domain"]["lower"])
            ax.plot(t, level - level[0] + 0.55, color=f"C{k}", lw=1.0,
                    label=f"parmps {dims}D, 0.55/{0.55 / spacing:.0f} m (less its reading "
                          f"at rest)")
        lower, upper = analysis.fluid_extent(case)
        tt = np.linspace(0.0, 0.12, 121)  # where the t^2 term holds (the runs: 0.07 s)
        ax.plot(tt, analysis.incompressible_start_level(
            tt, analysis.gauge_x(case, "H4") - lower[0], upper[-1] - lower[-1],
            upper[0] - lower[0], analysis.gravity(case)), "k--", lw=0.8,
            label="incompressible start, 0.55 + a t^2 / 2")
        ax.set_xlim(0.0, 0.45)
        ax.set_ylim(0.44, 0.56)
        ax.set_xlabel("t [s] after the release")
        ax.set_ylabel("H4 depth [m] (x = 2.638 m)")
        ax.legend(fontsize=7)
        ax.set_title("SPHERIC Test 2: the reservoir's gauge H4 before the front reaches the box")
        figure.tight_layout()
        figure.savefig(png, dpi=110)
        plt.close(figure)
        lines.append(f"plot: {png}")
    return "\n".join(lines)


def main():
    from parmps import validation
    check = validation.load("dam_break_3d")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("result", nargs="?", help="result.h5 of cases/dam_break_3d.toml")
    parser.add_argument("--origin", nargs="+", metavar="RESULT",
                        help="estimate the record's clock from H4 against these results (3D "
                             "case or section_2d.toml, each run to 0.35 s at least) and the "
                             "incompressible start, print it and exit")
    parser.add_argument("--origin-png", help="with --origin: where to draw H4 on both clocks")
    parser.add_argument("--png", help="where to write the plot (default: none)")
    parser.add_argument("--windows", type=float, metavar="SECONDS",
                        help="also print each sensor's mean over windows this long, from "
                             "0.4 s on, beside the record's")
    parser.add_argument("--section", type=float, nargs="+", metavar="T",
                        help="draw the (x, z) section through the sensors at these times")
    parser.add_argument("--section-png", default="section.png",
                        help="where --section draws (default section.png)")
    args = parser.parse_args()
    if args.origin:
        print(origin(args.origin, check, args.origin_png))
        return 0
    if args.result is None:
        parser.error("give a result, or --origin RESULT ...")
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
