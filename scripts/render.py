#!/usr/bin/env python3
"""Pictures of coupled runs: PNG snapshots and time series into docs/.

    python scripts/render.py out/membrane_tube out/box_in_flow [--docs docs] [--snapshots 4]

For each run directory (holding result.h5) it writes

- ``<stem>_snapshots.png``: particles coloured by pressure (walls and dummies
  grey, solid nodes outlined) with every body's springs drawn, at several times;
- ``<stem>_series.png``: the key time series. A body named "membrane": the
  vertical displacement of the mid-point of its lower row and the tube's
  relative area error; any other body: centroid displacement, centroid
  velocity and relative area error.
"""

import argparse
import logging
import tomllib
from pathlib import Path

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402

log = logging.getLogger("render")

FLUID, WALL, DUMMY, SOLID, INFLOW = 0, 1, 2, 3, 4


def load(path):
    with h5py.File(path, "r") as handle:
        case = tomllib.loads(handle["case"].attrs["toml"])
        frames = []
        for name in sorted(handle["frames"]):
            group = handle["frames"][name]
            frame = {key: group[key][()] for key in ("kind", "position", "pressure")}
            frame["time"] = float(group.attrs["time"])
            frame["solids"] = {body: group["solids"][body]["position"][()]
                               for body in group.get("solids", {})}
            frames.append(frame)
        bodies = {}
        for body in handle.get("solids", {}):
            group = handle["solids"][body]
            bodies[body] = {key: group[key][()] for key in group}
    return case, frames, bodies


def snapshots(case, frames, bodies, count, path, title):
    picks = np.unique(np.linspace(0, len(frames) - 1, count).round().astype(int))
    lower, upper = np.asarray(case["domain"]["lower"]), np.asarray(case["domain"]["upper"])
    aspect = (upper[1] - lower[1]) / (upper[0] - lower[0])
    moving = np.concatenate([f["pressure"][(f["kind"] == FLUID) | (f["kind"] == INFLOW) |
                                           (f["kind"] == SOLID)] for f in frames])
    vmax = float(np.percentile(moving, 99)) if len(moving) else 1.0
    width = 9.0
    fig, axes = plt.subplots(len(picks), 1, figsize=(width, len(picks) * (width * aspect + 0.5)),
                             squeeze=False)
    spacing = case["particles"]["spacing"]
    size = (72 * 0.55 * spacing * width / (upper[0] - lower[0])) ** 2
    for ax, k in zip(axes[:, 0], picks):
        frame = frames[k]
        kind, position = frame["kind"], frame["position"]
        fixed = (kind == WALL) | (kind == DUMMY)
        ax.scatter(*position[fixed].T, s=size, c="0.75", linewidths=0)
        live = ~fixed
        points = ax.scatter(*position[live].T, s=size, c=frame["pressure"][live], cmap="viridis",
                            vmin=0.0, vmax=max(vmax, 1e-12), linewidths=0)
        for body, nodes in frame["solids"].items():
            springs = bodies[body]["springs"]
            ax.add_collection(LineCollection(nodes[springs], colors="crimson", linewidths=0.6))
        ax.set_xlim(lower[0], upper[0])
        ax.set_ylim(lower[1], upper[1])
        ax.set_aspect("equal")
        ax.set_title(f"t = {frame['time']:.2f} s", fontsize=9)
        ax.tick_params(labelsize=7)
    fig.colorbar(points, ax=axes[:, 0].tolist(), label="pressure [Pa]", shrink=0.8)
    fig.suptitle(title, fontsize=10)
    fig.savefig(path, dpi=90, bbox_inches="tight")
    plt.close(fig)
    log.info("wrote %s", path)


def series(case, frames, bodies, path, title):
    specs = {spec.get("name") or f"body{k}": spec for k, spec in enumerate(case.get("body", []))}
    names = list(bodies)
    membrane = [name for name in names if name == "membrane"]
    if membrane:
        name = membrane[0]
        nx = specs[name]["nx"]
        times = np.array([f["time"] for f in frames])
        middle = np.array([f["solids"][name][nx // 2, 1] for f in frames])
        fig, (a, b) = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
        a.plot(times, 1e3 * (middle - middle[0]))
        a.set_ylabel("mid-point displacement [mm]")
        for load in specs[name].get("load", []):
            a.axvspan(load.get("start", 0.0), load.get("end", times[-1]), color="0.9")
        b.plot(bodies[name]["time"], bodies[name]["volume_error"])
        b.set_ylabel("tube area error (V - V0)/V0")
        b.set_xlabel("time [s]")
    else:
        fig, (a, b, c) = plt.subplots(3, 1, figsize=(7, 7.5), sharex=True)
        for name in names:
            t = bodies[name]["time"]
            centroid = bodies[name]["centroid"]
            a.plot(t, 1e3 * (centroid[:, 0] - centroid[0, 0]), label=f"{name} x")
            a.plot(t, 1e3 * (centroid[:, 1] - centroid[0, 1]), label=f"{name} y")
            velocity = np.gradient(centroid, t, axis=0)
            b.plot(t, velocity[:, 0], label=f"{name} u")
            b.plot(t, velocity[:, 1], label=f"{name} v")
            c.plot(t, bodies[name]["volume_error"], label=name)
        a.set_ylabel("centroid displacement [mm]")
        b.set_ylabel("centroid velocity [m/s]")
        c.set_ylabel("area error (V - V0)/V0")
        c.set_xlabel("time [s]")
        a.legend(fontsize=8)
        b.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    log.info("wrote %s", path)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path, help="run directories (with result.h5)")
    parser.add_argument("--docs", type=Path, default=Path(__file__).resolve().parents[1] / "docs")
    parser.add_argument("--snapshots", type=int, default=4)
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    args.docs.mkdir(parents=True, exist_ok=True)
    for run in args.runs:
        case, frames, bodies = load(run / "result.h5")
        stem = run.name
        title = case.get("title", stem)
        snapshots(case, frames, bodies, args.snapshots, args.docs / f"{stem}_snapshots.png", title)
        if bodies:
            series(case, frames, bodies, args.docs / f"{stem}_series.png", title)


if __name__ == "__main__":
    main()
