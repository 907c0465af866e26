"""Post-processing shared by the tests and the validation scripts."""

import os

import numpy as np

from parmps.core.particles import FLUID

DATA = os.path.join(os.path.dirname(os.path.dirname(__file__)), "data")


def martin_moyce():
    """Martin & Moyce (1952) n^2 = 2 surge front: arrays T = t sqrt(2g/a), Z = x/a."""
    table = np.loadtxt(os.path.join(DATA, "martin_moyce_1952_surge_front.csv"),
                       delimiter=",", comments="#", skiprows=4)
    return table[:, 0], table[:, 1]


def frames(path):
    """Every frame of a result file, each a dict of arrays sorted by id."""
    import h5py
    out = []
    with h5py.File(path, "r") as handle:
        for name in sorted(handle["frames"]):
            group = handle["frames"][name]
            order = np.argsort(group["id"][()], kind="stable")
            frame = {key: group[key][()][order] for key in
                     ("id", "kind", "position", "velocity", "pressure", "number_density")}
            frame.update({key: group.attrs[key] for key in ("time", "step", "dt")})
            out.append(frame)
    return out


def surge_front(path, wall_x, spacing):
    """Times and leading-edge x positions of the fluid (max x of fluid plus half a spacing)."""
    times, fronts = [], []
    for frame in frames(path):
        fluid = frame["kind"] == FLUID
        times.append(frame["time"])
        fronts.append(frame["position"][fluid, 0].max() + 0.5 * spacing - wall_x)
    return np.array(times), np.array(fronts)


def dam_break_error(path, column_width, wall_x, spacing, gravity=9.81, t_max=3.0):
    """RMS relative error of the simulated front against Martin & Moyce for T <= t_max.

    Returns (rms, T_sim, Z_sim, T_exp, Z_exp).
    """
    times, fronts = surge_front(path, wall_x, spacing)
    scale = np.sqrt(2.0 * gravity / column_width)
    t_sim, z_sim = times * scale, fronts / column_width
    t_exp, z_exp = martin_moyce()
    keep = t_exp <= t_max
    if t_sim[-1] < t_exp[keep][-1]:
        raise ValueError(f"the run ends at T = {t_sim[-1]:.3g}, before T = {t_exp[keep][-1]}")
    z_at = np.interp(t_exp[keep], t_sim, z_sim)
    rms = float(np.sqrt(np.mean(((z_at - z_exp[keep]) / z_exp[keep]) ** 2)))
    return rms, t_sim, z_sim, t_exp, z_exp


def hydrostatic_error(path, depth, density, gravity, settle_time, spacing):
    """Time-averaged pressure error against rho g (H - y) after ``settle_time``.

    Each particle's error is taken at its current depth in every frame and
    averaged over the frames, so particles that drift are compared with the
    pressure where they are. Returns (bottom error, RMS error), both relative to
    rho g H: the bottom error is the mean over the initial bottom fluid row; the
    RMS runs over every fluid particle but the initial top row, where the
    free-surface condition sets P = 0 half a spacing below the surface.
    """
    all_frames = frames(path)
    selected = [f for f in all_frames if f["time"] >= settle_time]
    if not selected:
        raise ValueError(f"no frame after t = {settle_time}")
    first = all_frames[0]
    fluid = first["kind"] == FLUID
    y0 = first["position"][:, 1]
    error = np.mean([f["pressure"] - density * gravity * (depth - f["position"][:, 1])
                     for f in selected], axis=0)
    scale = density * gravity * depth
    bottom = fluid & (y0 < y0[fluid].min() + 0.5 * spacing)
    interior = fluid & (y0 < depth - spacing)
    rms = np.sqrt(np.mean(error[interior] ** 2)) / scale
    return float(error[bottom].mean() / scale), float(rms)


def escaped(path, lower, upper):
    """Number of fluid particles outside the rectangle [lower, upper] in any frame."""
    count = 0
    for frame in frames(path):
        fluid = frame["kind"] == FLUID
        position = frame["position"][fluid]
        count = max(count, int(np.count_nonzero(np.any((position < lower) |
                                                       (position > upper), axis=1))))
    return count
