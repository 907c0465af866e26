#!/usr/bin/env python3
"""Plot a run's probes: one panel per probe kind, every probe of that kind in it.

    scripts/plot_probes.py OUT [--probes P1,P2,...] [--png OUT/probes.png]

OUT is a run's output directory (or its result.h5). Reads /probes/<name>/time and
value from result.h5 (OUT/probes/<name>.csv hold the same rows); values in SI units
(pressure in Pa, level in m, force in N per metre of depth, both components).
"""

import argparse
import os
import sys



def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", help="a run's output directory or its result.h5")
    parser.add_argument("--probes", default="", help="comma-separated names (default: all)")
    parser.add_argument("--png", default=None, help="default: OUT/probes.png")
    args = parser.parse_args()

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    import parmps
    from parmps.result import result_path
    path = result_path(args.output)
    png = args.png or os.path.join(os.path.dirname(path), "probes.png")
    wanted = [name for name in args.probes.split(",") if name]
    series = {}
    with parmps.open_result(path) as result:
        if not result.probes:
            print(f"{path} has no probes", file=sys.stderr)
            return 1
        for name, probe in result.probes.items():
            if wanted and name not in wanted:
                continue
            series[name] = (probe.attrs["kind"], probe.attrs["units"], probe.time, probe.value)
    kinds = sorted({kind for kind, *_ in series.values()})
    figure, axes = plt.subplots(len(kinds), 1, figsize=(8, 3 * len(kinds)), dpi=110,
                                sharex=True, squeeze=False)
    for ax, kind in zip(axes[:, 0], kinds):
        for name, (k, units, t, value) in series.items():
            if k != kind:
                continue
            if value.ndim == 2:
                for c, label in enumerate("xy"):
                    ax.plot(t, value[:, c], lw=0.8, label=f"{name} {label}")
            else:
                ax.plot(t, value, lw=0.8, label=name)
            ax.set_ylabel(f"{kind} [{units}]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[-1, 0].set_xlabel("t [s]")
    figure.tight_layout()
    figure.savefig(png)
    print(f"wrote {png}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
