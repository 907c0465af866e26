#!/usr/bin/env python3
"""SPHERIC Test 2 (the 3D dam break against a box): a result against Kleefsman et al. (2005).

    python validation/dam_break_3d/plot.py OUT/result.h5 [--png docs/dam_break_3d.png]

Run the case first, e.g. at 0.55/10 m on 2 ranks:

    ./scripts/run cases/dam_break_3d.toml --set particles.spacing=0.055 -o out/dam_break_3d_10

Prints, per sensor, the arrival (P1-P4), the means over the compared windows and the
peak of the 10 ms running mean, simulated beside measured; plots P1-P8 over the record
and the level gauges H1-H4; exits 1 when a target of validation.toml is missed.
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
    for name, row in metrics.items():
        if "arrival" in row and not abs(row["arrival_error"]) <= tolerance["arrival"]:
            missed.append(f"{name} arrival {row['arrival']:.3f} s against "
                          f"{row['arrival_measured']:.3f} s")
        limit = tolerance["front_mean"] if "arrival" in row else tolerance["top_mean"]
        for mean in row["means"]:
            if not abs(mean["error"]) <= limit:
                missed.append(f"{name} mean over {mean['window'][0]:g}-{mean['window'][1]:g} s "
                              f"{mean['error']:+.1%} (limit {limit:.0%})")
    return missed


def table(metrics):
    lines = ["sensor  arrival [s] (exp)   means [Pa] sim / exp (error) per window      "
             "peak 10 ms [Pa] (exp) at t [s]"]
    for name, row in metrics.items():
        arrival = (f"{row['arrival']:.3f} ({row['arrival_measured']:.3f})"
                   if "arrival" in row else "-")
        means = "; ".join(f"{m['window'][0]:g}-{m['window'][1]:g}: {m['mean']:.0f} / "
                          f"{m['mean_measured']:.0f} ({m['error']:+.1%})" for m in row["means"])
        lines.append(f"{name:6}  {arrival:18}  {means:50}  {row['peak']:.0f} "
                     f"({row['peak_measured']:.0f}) at {row['peak_time']:.3f} "
                     f"({row['peak_time_measured']:.3f})")
    return "\n".join(lines)


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
    for k, name in enumerate(f"H{i}" for i in range(1, 5)):
        ax = axes.flat[8 + k]
        t, level = analysis.read_probe(path, name)
        ax.plot(t, level, color="C1", lw=0.8)
        ax.set_title(f"{name} (level; record not given)")
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
    args = parser.parse_args()
    metrics = check.measure(args.result)
    print(table(metrics))
    if args.png:
        plot(args.result, check, args.png)
        print(f"plot: {args.png}")
    missed = judge(metrics, check.tolerance)
    for sentence in missed:
        print(f"missed: {sentence}")
    return 1 if missed else 0


if __name__ == "__main__":
    sys.exit(main())
