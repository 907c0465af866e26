#!/usr/bin/env python3
"""Pictures of coupled runs: PNG snapshots and time series into docs/.

    python scripts/render.py out/membrane_tube out/box_in_flow [--docs docs] [--snapshots 4]

For each run directory (holding result.h5) it writes

- ``<stem>_snapshots.png``: particles coloured by pressure (walls and dummies
  grey, solid nodes outlined) with every body's springs drawn, at several times;
- ``<stem>_series.png``: the key time series. A body named "membrane": the
  vertical displacement of the mid-point of its lower row and the tube's
  relative area error; any other body: centroid displacement, centroid
  velocity, bend (how far the middle row of nodes runs ahead of the end rows
  along the flow) and relative area error;
- ``<stem>_shape.png`` (lattice bodies that are not the membrane): the body's
  nodes and springs at the snapshot times, each drawn about its centroid, so
  the change of shape is visible at the scale of the body.

Sizes are kept small (the pictures are committed): low dpi and small markers.
"""

import argparse
import io
import logging
import tomllib
from pathlib import Path

import parmps
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.collections import LineCollection  # noqa: E402
from PIL import Image  # noqa: E402  (matplotlib's own dependency)

log = logging.getLogger("render")

FLUID, WALL, DUMMY, SOLID, INFLOW = 0, 1, 2, 3, 4
DPI = 72  # committed pictures stay well under 150 KB


def load(path):
    with parmps.open_result(path) as result:
        case = tomllib.loads(result.case_text)
        frames = []
        for frame in result.frames:
            data = {key: frame[key] for key in ("kind", "position", "pressure")}
            data["time"] = frame.time
            data["solids"] = {body: frame.bodies[body]["position"] for body in frame.bodies}
            frames.append(data)
        bodies = {name: dict(body) for name, body in result.bodies.items()}
    return case, frames, bodies


def snapshots(case, frames, bodies, count, path, title):
    picks = np.unique(np.linspace(0, len(frames) - 1, count).round().astype(int))
    lower, upper = np.asarray(case["domain"]["lower"]), np.asarray(case["domain"]["upper"])
    aspect = (upper[1] - lower[1]) / (upper[0] - lower[0])
    moving = np.concatenate([f["pressure"][(f["kind"] == FLUID) | (f["kind"] == INFLOW) |
                                           (f["kind"] == SOLID)] for f in frames])
    vmax = float(np.percentile(moving, 99)) if len(moving) else 1.0
    width = 6.5
    fig, axes = plt.subplots(len(picks), 1, figsize=(width, len(picks) * (width * aspect + 0.35)
                                                     + 0.6), squeeze=False, layout="constrained")
    spacing = case["particles"]["spacing"]
    size = (72 * 0.5 * spacing * width / (upper[0] - lower[0])) ** 2
    for ax, k in zip(axes[:, 0], picks):
        frame = frames[k]
        kind, position = frame["kind"], frame["position"]
        # Walls in grey; dummies (behind them) are left out to keep the file small.
        ax.scatter(*position[kind == WALL].T, s=size, c="0.7", linewidths=0)
        live = (kind != WALL) & (kind != DUMMY)
        points = ax.scatter(*position[live].T, s=size, c=frame["pressure"][live], cmap="viridis",
                            vmin=0.0, vmax=max(vmax, 1e-12), linewidths=0)
        for body, nodes in frame["solids"].items():
            springs = bodies[body]["springs"]
            ax.add_collection(LineCollection(nodes[springs], colors="crimson", linewidths=0.5))
            ax.plot(*nodes.T, "o", color="crimson", markersize=1.2, linestyle="none")
        ax.set_xlim(lower[0], upper[0])
        ax.set_ylim(lower[1], upper[1])
        ax.set_aspect("equal")
        ax.set_title(f"t = {frame['time']:.2f} s", fontsize=9)
        ax.tick_params(labelsize=7)
    fig.colorbar(points, ax=axes[:, 0].tolist(), label="pressure [Pa]", shrink=0.6,
                 orientation="horizontal", aspect=40)
    fig.suptitle(title, fontsize=10)
    save(fig, path)
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
        fig, (a, b, d, c) = plt.subplots(4, 1, figsize=(7, 8.5), sharex=True)
        times = np.array([f["time"] for f in frames])
        for name in names:
            t = bodies[name]["time"]
            centroid = bodies[name]["centroid"]
            a.plot(t, 1e3 * (centroid[:, 0] - centroid[0, 0]), label=f"{name} x")
            a.plot(t, 1e3 * (centroid[:, 1] - centroid[0, 1]), label=f"{name} y")
            velocity = np.gradient(centroid, t, axis=0)
            b.plot(t, velocity[:, 0], label=f"{name} u")
            b.plot(t, velocity[:, 1], label=f"{name} v")
            c.plot(t, bodies[name]["volume_error"], label=name)
            spec = specs.get(name, {})
            if "nx" in spec and "ny" in spec:
                bends = np.array([bend(f["solids"][name], spec["nx"], spec["ny"], case)
                                  for f in frames])
                d.plot(times, 1e3 * bends, "o-", markersize=2, label=name)
        a.set_ylabel("centroid displacement [mm]")
        b.set_ylabel("centroid velocity [m/s]")
        d.set_ylabel("bend [mm]")
        c.set_ylabel("area error (V - V0)/V0")
        c.set_xlabel("time [s]")
        a.legend(fontsize=8)
        b.legend(fontsize=8)
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    save(fig, path)
    log.info("wrote %s", path)


def save(fig, path):
    """Write a PNG with a 256-colour palette: a third of the RGBA size for scatter plots."""
    buffer = io.BytesIO()
    fig.savefig(buffer, dpi=DPI, format="png")
    plt.close(fig)
    buffer.seek(0)
    Image.open(buffer).convert("RGB").quantize(colors=256).save(path, optimize=True)


def flow_axis(case):
    """Unit vector of the flow (the first inlet's direction), or +x without an inlet."""
    inlets = case.get("inlet", [])
    if not inlets:
        return np.array([1.0, 0.0])
    velocity = np.asarray(inlets[0]["velocity"], dtype=float)
    return velocity / np.linalg.norm(velocity)


def bend(nodes, nx, ny, case):
    """How far the middle of a lattice body runs ahead of its ends, along the flow.

    Rows of nodes across the flow: the mean position of the middle row minus
    the mean of the two end rows, projected on the flow direction. Zero for
    the undeformed box; positive for a parachute (cup open upstream).
    """
    axis = flow_axis(case)
    along = (nodes[:nx * ny] @ axis).reshape(ny, nx)   # [row j (y), column i (x)]
    if abs(axis[1]) > abs(axis[0]):
        along = along.T                                # across the flow is x: index i
    middle = along[along.shape[0] // 2].mean()
    ends = 0.5 * (along[0].mean() + along[-1].mean())
    return middle - ends


def shapes(case, frames, bodies, count, path, title):
    """Each lattice body's nodes and springs about its centroid at several times."""
    specs = {spec.get("name") or f"body{k}": spec for k, spec in enumerate(case.get("body", []))}
    names = [name for name in bodies if name != "membrane" and "nx" in specs.get(name, {})]
    if not names:
        return
    picks = np.unique(np.linspace(0, len(frames) - 1, count).round().astype(int))
    colours = plt.cm.viridis(np.linspace(0.0, 0.9, len(picks)))
    fig, axes = plt.subplots(1, len(names), figsize=(3.6 * len(names), 5.0), squeeze=False,
                             layout="constrained")
    for ax, name in zip(axes[0], names):
        springs = bodies[name]["springs"]
        nx, ny = specs[name]["nx"], specs[name]["ny"]
        grid = np.arange(nx * ny).reshape(ny, nx)
        outline = np.concatenate([grid[0], grid[1:, -1], grid[-1, -2::-1], grid[-2:0:-1, 0],
                                  grid[:1, 0]])
        for colour, k in zip(colours, picks):
            nodes = frames[k]["solids"][name]
            centred = 1e3 * (nodes - nodes.mean(axis=0))
            if k == picks[-1]:  # springs of the last shape only: four meshes would hide it
                ax.add_collection(LineCollection(centred[springs], colors=[colour],
                                                 linewidths=0.4))
            ax.plot(*centred[outline].T, "-", color=colour, linewidth=1.2,
                    label=f"t = {frames[k]['time']:.2f} s")
            ax.plot(*centred.T, "o", color=colour, markersize=2.0, linestyle="none")
        ax.autoscale()
        axis = flow_axis(case)
        x0, x1 = ax.get_xlim()
        y0, y1 = ax.get_ylim()
        ax.set_ylim(y0, y1 + 0.15 * (y1 - y0))  # room for the flow arrow above the body
        start = np.array([0.5 * (x0 + x1), y1 + 0.08 * (y1 - y0)]) - 5 * axis
        ax.annotate("flow", xytext=start, xy=start + 10 * axis, fontsize=7, color="0.3",
                    va="center", arrowprops=dict(arrowstyle="->", color="0.3"))
        ax.set_aspect("equal")
        ax.set_xlabel("x - centroid [mm]")
        ax.set_ylabel("y - centroid [mm]")
        ax.set_title(name, fontsize=9)
        ax.legend(fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2)
    fig.suptitle(title, fontsize=10)
    save(fig, path)
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
            shapes(case, frames, bodies, args.snapshots, args.docs / f"{stem}_shape.png", title)


if __name__ == "__main__":
    main()
