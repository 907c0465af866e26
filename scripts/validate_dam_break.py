#!/usr/bin/env python3
"""Dam break against Martin & Moyce (1952): run the case, plot the surge front.

    scripts/validate_dam_break.py [--result OUT/result.h5] [--spacing L0] [--ranks N]
                                  [--column-width A] [--gate-speed V]
                                  [--png docs/dam_break_validation.png]

What is compared, the metric and its tolerance: validation/dam_break/. Without
--result it runs the case named there to the T of its [run] table with frames at
its interval, on --ranks ranks, then writes a PNG of Z = x/a against
T = t sqrt(2g/a), simulation and experiment, with the RMS relative error in the
title, and prints the error at every measured point. --column-width scales the
whole scene (column, tank, domain) to another a at the same l0/a, e.g. 0.05715 for
the experiment's own 2.25 in; --spacing is l0 at the case's own column width.
--gate-speed adds a gate (a wall box 4 l0 thick against the column's free side,
2.25 a tall) lifted at V m/s from t = 0 until its bottom clears the column: a
sensitivity study of the release, not a fit.
"""

import argparse
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def main():
    from parmps import validation
    from parmps.tools import analysis

    check = validation.load("dam_break")
    case = check.case()
    lower, upper = analysis.fluid_extent(case)
    case_width = upper[0] - lower[0]

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--result", help="an existing result.h5 of the dam break")
    parser.add_argument("--spacing", type=float, default=None,
                        help=f"particle spacing l0 [m] at the case's a = {case_width:g} m "
                             "(scaled with --column-width)")
    parser.add_argument("--ranks", type=int, default=1)
    parser.add_argument("--column-width", type=float, default=case_width,
                        help=f"column width a [m]; the scene is scaled from the case's "
                             f"{case_width:g} m")
    parser.add_argument("--gate-speed", type=float, default=None,
                        help="lift a gate at this speed [m/s] instead of releasing at once")
    parser.add_argument("--png", default=os.path.join(ROOT, "docs", "dam_break_validation.png"))
    args = parser.parse_args()
    if args.gate_speed is not None and (args.gate_speed <= 0 or args.result):
        parser.error("--gate-speed needs a positive speed and no --result")

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    result = args.result
    if result is None:
        result = run_case(check, args, case_width)
    measured = check.measure(result)
    ran = analysis.result_case(result)
    lower, upper = analysis.fluid_extent(ran)
    width, spacing = upper[0] - lower[0], ran["particles"]["spacing"]
    t_sim, z_sim = measured["T"], measured["Z"]
    t_exp, z_exp = measured["T_reference"], measured["Z_reference"]
    rms, best, best_rms = measured["rms"], measured["delay"], measured["rms_delayed"]
    keep = t_exp <= measured["compare_until"]

    figure, axes = plt.subplots(figsize=(6, 4.2), dpi=110)
    axes.plot(t_sim, z_sim, "-", color="tab:blue",
              label=f"parmps MPS, l0 = a/{width / spacing:.0f}")
    # The simulated column is released at once, and its front leads the
    # experiment's by a nearly constant time; the best constant delay is shown
    # for reference only (the error in the title is that of the unshifted curve).
    axes.plot(t_sim + best, z_sim, ":", color="tab:blue",
              label=f"same, delayed by T = {best:.2f} ({100 * best_rms:.1f} %)")
    axes.plot(t_exp, z_exp, "o", color="black", mfc="none", label="Martin & Moyce (1952)")
    axes.set_xlabel(r"$T = t\sqrt{2g/a}$")
    axes.set_ylabel(r"$Z = x/a$")
    axes.set_xlim(0, 3.5)
    axes.set_ylim(1, 4.3)
    axes.grid(alpha=0.3)
    axes.legend(loc="upper left")
    axes.set_title(f"Dam break surge front: RMS relative error {100 * rms:.1f} % "
                   f"(T <= {measured['compare_until']:g})")
    figure.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(args.png)), exist_ok=True)
    figure.savefig(args.png)
    print("    T   Z exp   Z sim   error")
    for t, z in zip(t_exp[keep], z_exp[keep]):
        z_at = np.interp(t, t_sim, z_sim)
        print(f"{t:5.2f}  {z:6.2f}  {z_at:6.2f}  {100 * (z_at - z) / z:+5.1f} %")
    print(f"RMS relative error of the surge front for T <= {measured['compare_until']:g}: "
          f"{100 * rms:.2f} % (reported, not judged: the record's t = 0 is undefined)")
    low, high = check.tolerance["delay"]
    print(f"with the best constant delay T = {best:.2f} (bounds at l0 = a/20: {low:g}-{high:g}): "
          f"{100 * best_rms:.2f} % (bound {100 * check.tolerance['rms_delayed']:.0f} %)")
    print(f"wrote {args.png}")
    return 0


def run_case(check, args, case_width):
    """Run the validation's case as asked on the command line; returns the result file."""
    from parmps import validation
    from parmps.tools import analysis

    raw = check.raw_case()
    scale = args.column_width / case_width
    spacing = (args.spacing or raw["particles"]["spacing"]) * scale
    overrides = [f"particles.spacing={spacing!r}"]
    if scale != 1.0:
        overrides += validation.scaled_overrides(raw, scale)
    case = check.case(overrides)
    # Froude similarity: times scale as sqrt(a), lengths as a.
    end_time = check.run["until"] / analysis.dam_break_time_scale(case)
    interval = check.run["output_interval"] * scale ** 0.5
    directory = os.path.join(ROOT, "out", "dam_break_validation")
    case_path = check.case_path
    if args.gate_speed is not None:
        case_path = case_with_gate(check.case_path, directory, case, args.gate_speed)
    from parmps.validation import launch
    sets = [f"time.output_interval={interval!r}"] + overrides
    record = launch.run(case_path, directory, sets, end_time, ranks=args.ranks, timeout=None,
                        root=ROOT)
    if record["status"] != 0:
        sys.exit(f"{record['command']}: {record['outcome']}")
    return os.path.join(directory, "result.h5")


def case_with_gate(case_path, directory, case, speed):
    """Write the case plus a gate lifted at ``speed``; returns the new case's path.

    ``case``: the validated case as it will run (scaled), which places the gate
    against the column's free side.
    """
    from parmps.tools import analysis

    lower, upper = analysis.fluid_extent(case)
    width = upper[0] - lower[0]
    spacing = case["particles"]["spacing"]
    height = 2.25 * width
    with open(case_path) as handle:
        text = handle.read()
    text += f"""
# The gate of scripts/validate_dam_break.py --gate-speed {speed:g}.
[[wall_box]]
lower = [{upper[0]!r}, {lower[1]!r}]
upper = [{upper[0] + 4 * spacing!r}, {lower[1] + height!r}]
wall_layers = 2
velocity = [0.0, {speed!r}]
move_end = {height / speed!r}
"""
    os.makedirs(directory, exist_ok=True)
    path = os.path.join(directory, "dam_break_gate.toml")
    with open(path, "w") as handle:
        handle.write(text)
    return path


if __name__ == "__main__":
    sys.exit(main())
