"""Post-processing shared by the tests and the validation scripts.

The validation metrics take a result file and the case that made it (a validated
case, as ``parmps.schema.validate`` returns it; ``result_case`` reads the one a result
file was run with, overrides included). Every physical constant they need (column
width, depth, density, gravity, spacing) comes from that case, never from a constant
here. Which metric judges which case, and its tolerances: ``validation/<name>/``.
"""

import math

import numpy as np

from parmps.core.particles import FLUID
from parmps.io.frames import read_frames
from parmps.result import open_result


# --------------------------------------------------------------------------
# Reading results

def result_case(path):
    """The validated case a result file was run with (its --set and --end-time included)."""
    with open_result(path) as result:
        return result.case



def run_summary(path):
    """Loop wall time, steps, last time, finiteness and (with a fluid) mean KSP iterations
    of a result file.

    An empty dict when the file is missing or has no diagnostics (a run that never started).
    """
    from parmps.errors import CaseError
    try:
        with open_result(path) as result:
            diagnostics = result.diagnostics
            wall = diagnostics["wall_seconds"]
            finite = True
            if len(result.frames):
                last = result.frames[-1]
                finite = bool(np.all(np.isfinite(last.position)) and
                              np.all(np.isfinite(last.velocity)))
            steps = len(wall)
            summary = {"wall": float(wall[-1]) if steps else 0.0,
                       "steps": int(steps),
                       "end": float(diagnostics["time"][-1]) if steps else 0.0,
                       "finite": finite}
            if "ksp_iterations" in diagnostics:  # a solid-only run solves no pressure
                summary["ksp_mean"] = (float(np.mean(diagnostics["ksp_iterations"]))
                                       if steps else 0.0)
            return summary
    except (CaseError, OSError, KeyError):
        return {}


def reference_table(path):
    """A reference CSV (``#`` comment lines naming its source, then a header row) as columns."""
    with open(path) as handle:
        lines = [line.strip() for line in handle if line.strip() and not line.startswith("#")]
    names = [name.strip() for name in lines[0].split(",")]
    values = np.array([[float(v) for v in line.split(",")] for line in lines[1:]])
    return {name: values[:, k] for k, name in enumerate(names)}


def log_slope(x, y):
    """Least-squares slope of log y against log x (an observed order); NaN below two points."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    keep = (x > 0) & (y > 0) & np.isfinite(x) & np.isfinite(y)
    if keep.sum() < 2:
        return math.nan
    return float(np.polyfit(np.log(x[keep]), np.log(y[keep]), 1)[0])


# --------------------------------------------------------------------------
# What a case says about its own geometry

def gravity(case):
    """|g| [m/s^2] of a case."""
    return float(np.linalg.norm(case["physics"]["gravity"]))


def fluid_extent(case):
    """Lower-left and upper-right corners of the bounding box of a case's fluid blocks."""
    from parmps.geometry.walls import shape_bounds

    boxes = [shape_bounds(block) for block in case["fluid_block"]]
    boxes = [box for box in boxes if box is not None]  # a mesh's is known once it is read
    if not boxes:
        raise ValueError("the case has no [[fluid_block]] of a known extent")
    lower = np.min([box[0] for box in boxes], axis=0)
    upper = np.max([box[1] for box in boxes], axis=0)
    return lower, upper


def dam_break_time_scale(case):
    """sqrt(2 g / a) [1/s] of a dam break: T = t sqrt(2 g / a), a the column's width."""
    lower, upper = fluid_extent(case)
    return math.sqrt(2.0 * gravity(case) / (upper[0] - lower[0]))


def column_time_scale(case):
    """sqrt(g / H) [1/s] of a water column H high: t* = t sqrt(g / H) (Lobovsky et al.)."""
    lower, upper = fluid_extent(case)
    return math.sqrt(gravity(case) / (upper[1] - lower[1]))


# --------------------------------------------------------------------------
# Long runs: the mechanical energy and the particles' speeds

def long_run_energy(path, case, report_at=(5.0, 10.0, 15.0, 20.0)):
    """A violent run judged by what no wall or gravity can do: raise the fluid's energy.

    From the diagnostics (docs/design.md §1.8): the budget ``fluid_energy + body_energy -
    boundary_work`` at each frame's step, and ``energy_rise``, its largest rise from one frame
    to the next over the fluid's initial energy E0; ``energy_end`` and ``energy_at`` (E/E0 at
    t sqrt(g/H) = each of ``report_at``, H the column's height). From the frames, the fluid's
    speeds over 2 sqrt(g H) (the dam break's front speed in shallow water): ``speed_999``, the
    largest 99.9th percentile of a frame, and ``speed_max``, the largest speed; ``removed``,
    the fluid removed outside the domain over the fluid at t = 0; ``end`` in t sqrt(g/H).
    """
    from parmps.fluid import energy
    from parmps.result import open_result
    scale = column_time_scale(case)
    lower, upper = fluid_extent(case)
    front_speed = 2.0 * math.sqrt(gravity(case) * (upper[1] - lower[1]))
    with open_result(path) as result:
        d = result.diagnostics
        budget = energy.budget(d)
        steps = d["step"]
        p999, largest, frame_steps = [], [], []
        for frame in result.frames:
            speed = np.linalg.norm(frame.velocity[frame.kind == 0], axis=1)
            p999.append(np.quantile(speed, 0.999) if len(speed) else 0.0)
            largest.append(speed.max() if len(speed) else 0.0)
            frame_steps.append(frame.step)
        rows = np.searchsorted(steps, np.asarray(frame_steps[1:]))
        rows = rows[rows < len(steps)]
        at_frames = budget[rows]
        initial = d["fluid_energy"][0]
        time = d["time"] * scale
        return {"energy_rise": float(np.diff(at_frames).max() / initial)
                if len(at_frames) > 1 else 0.0,
                "energy_end": float(d["fluid_energy"][-1] / initial),
                "energy_at": {f"{t:g}": float(np.interp(t, time, d["fluid_energy"]) / initial)
                              for t in report_at if t <= time[-1]},
                "speed_999": float(max(p999) / front_speed),
                "speed_max": float(max(largest) / front_speed),
                "removed": float(d["n_escaped"][-1] / (d["n_fluid"][0] + d["n_escaped"][0])),
                "end": float(time[-1])}


# --------------------------------------------------------------------------
# Dam break: the surge front against Martin & Moyce

def front(frame, wall_x, spacing, floor=None, band=None):
    """The surge front of one frame: the largest x of the fluid particles plus half a
    spacing, measured from the wall at ``wall_x``. With ``floor`` and ``band``, only the
    fluid within ``band`` of the floor counts (the front on the floor, once a jet has
    left it). ``frame``: a frame of :func:`parmps.open_result` or a dict of its arrays."""
    position = frame["position"][frame["kind"] == FLUID]
    if floor is not None:
        position = position[position[:, 1] < floor + band]
    return float(position[:, 0].max() + 0.5 * spacing - wall_x)


def surge_front(path, wall_x, spacing, floor=None, band=None):
    """Times and surge fronts (:func:`front`) of every frame of a result."""
    times, fronts = [], []
    with open_result(path) as result:
        for frame in result.frames:
            times.append(frame.time)
            fronts.append(front(frame, wall_x, spacing, floor, band))
    return np.array(times), np.array(fronts)


def surge_front_error(path, case, reference, compare_until=3.0, delay_range=(0.0, 0.6),
                      delay_step=0.005):
    """The dam break's front Z = x/a against T = t sqrt(2 g / a), compared with a measured one.

    ``reference``: a CSV with columns T and Z (Martin & Moyce's). The column (width a,
    its left side the wall the front is measured from), gravity and l0 come from
    ``case``. Returns a dict: ``rms``, the RMS relative error of the front at the
    measured points with T <= compare_until; ``rms_delayed`` and ``delay``, the same
    with the best constant delay of the experiment's start in ``delay_range`` (the
    simulated release is instant, the experiment's is not); the curves ``T``, ``Z``
    (simulated) and ``T_reference``, ``Z_reference``.
    """
    lower, upper = fluid_extent(case)
    width = upper[0] - lower[0]
    times, fronts = surge_front(path, lower[0], case["particles"]["spacing"])
    t_sim, z_sim = times * dam_break_time_scale(case), fronts / width
    table = reference_table(reference)
    t_ref, z_ref = table["T"], table["Z"]
    keep = t_ref <= compare_until
    if t_sim[-1] < t_ref[keep][-1]:
        raise ValueError(f"the run ends at T = {t_sim[-1]:.3g}, before T = {t_ref[keep][-1]}")

    def rms(delay):
        z_at = np.interp(t_ref[keep] - delay, t_sim, z_sim)
        return float(np.sqrt(np.mean(((z_at - z_ref[keep]) / z_ref[keep]) ** 2)))

    count = int(round((delay_range[1] - delay_range[0]) / delay_step)) + 1
    delays = np.linspace(delay_range[0], delay_range[1], count)
    delayed = [rms(d) for d in delays]
    best = int(np.argmin(delayed))
    return {"rms": rms(0.0), "rms_delayed": delayed[best], "delay": float(delays[best]),
            "T": t_sim, "Z": z_sim, "T_reference": t_ref, "Z_reference": z_ref,
            "compare_until": compare_until}


# --------------------------------------------------------------------------
# Still tank: pressure against rho g (H - y)

def hydrostatic_pressure_error(path, case, settle_time):
    """Pressure error of a still tank after ``settle_time``, relative to rho g H.

    The water's floor and surface (so H) and its width W (its horizontal area in 3D) are
    the first frame's: half a spacing below its lowest and above its highest fluid
    particles, and the bottom row's particles times l0^(d-1) (a box's width; a vessel of any
    shape with upright walls, its cross-section as the lattice samples it); density,
    gravity and l0 come from ``case``. Each particle's pressure is compared in every frame
    with the weight of the water above it: rho g l0^d (N_above + 1/2) / W, N_above the fluid
    particles higher than it. That reference follows the column if it settles or expands,
    which ``height_drift`` reports on its own. Returns a dict:

    - ``bottom``: the time-averaged error, mean over the initial bottom fluid row;
    - ``rms``: RMS over every fluid particle but the initial top row (the free-surface
      particles, whose pressure P = 0 on themselves, the original condition, would
      have set) of the time-averaged error;
    - ``bottom_std``, ``bottom_series``, ``bottom_times``: the bottom row's mean error
      frame by frame and its standard deviation over time (the pressure noise);
    - ``noise``: RMS over particles and frames of the instantaneous error;
    - ``speed_rms``: RMS fluid speed in the last frame (the surface "boiling");
    - ``height_drift``: the column's mean height 2 <y - floor> over the fluid,
      averaged over the frames after ``settle_time``, relative to its value in
      the first frame, minus 1 (positive: the column has expanded).
    """
    spacing = case["particles"]["spacing"]
    density, g = case["fluid"]["density"], gravity(case)
    all_frames = read_frames(path)
    selected = [f for f in all_frames if f["time"] >= settle_time]
    if not selected:
        raise ValueError(f"no frame after t = {settle_time}")
    first = all_frames[0]
    fluid = first["kind"] == FLUID
    # The vertical is the last axis (y in 2D, z in 3D).
    y0 = first["position"][:, -1]
    dimension = first["position"].shape[1]
    floor = float(y0[fluid].min()) - 0.5 * spacing
    surface = float(y0[fluid].max()) + 0.5 * spacing
    depth = surface - floor
    bottom = fluid & (y0 < y0[fluid].min() + 0.5 * spacing)
    interior = fluid & (y0 < surface - spacing)
    scale = density * g * depth
    width = np.count_nonzero(bottom) * spacing ** (dimension - 1)
    particle_weight = density * g * spacing ** dimension / width

    def weight_above(frame):
        # Zero for every particle but the fluid, which is all the errors below read.
        is_fluid = frame["kind"] == FLUID
        height = frame["position"][:, -1]
        above = np.zeros(len(height))
        order = np.argsort(-height[is_fluid], kind="stable")
        rank = np.empty(len(order))
        rank[order] = np.arange(len(order))
        above[is_fluid] = particle_weight * (rank + 0.5)
        return above

    errors = np.array([(f["pressure"] - weight_above(f)) / scale for f in selected])
    mean_error = errors.mean(axis=0)
    series = errors[:, bottom].mean(axis=1)
    last = all_frames[-1]
    speed = np.sqrt((last["velocity"][last["kind"] == FLUID] ** 2).sum(axis=1))

    def column_height(frame):
        return 2.0 * float(np.mean(frame["position"][frame["kind"] == FLUID, -1] - floor))

    height = np.mean([column_height(f) for f in selected]) / column_height(first) - 1.0
    return {"bottom": float(mean_error[bottom].mean()),
            "rms": float(np.sqrt(np.mean(mean_error[interior] ** 2))),
            "bottom_std": float(np.std(series)),
            "bottom_series": series.tolist(),
            "bottom_times": [float(f["time"]) for f in selected],
            "noise": float(np.mean(np.sqrt(np.mean(errors[:, interior] ** 2, axis=1)))),
            "speed_rms": float(np.sqrt(np.mean(speed ** 2))),
            "height_drift": float(height)}


def escaped(path, lower, upper):
    """Number of fluid particles outside the rectangle [lower, upper] in any frame."""
    count = 0
    for frame in read_frames(path):
        fluid = frame["kind"] == FLUID
        position = frame["position"][fluid]
        count = max(count, int(np.count_nonzero(np.any((position < lower) |
                                                       (position > upper), axis=1))))
    return count


# --------------------------------------------------------------------------
# Solids

def solid_series(path, body):
    """A body's per-step series (time, volume_error, centroid, fluid_force, ...)."""
    with open_result(path) as result:
        group = result.bodies[body]
        return {key: group[key] for key in group if key != "springs"}


def volume_error(path, case):
    """Largest |V - V0|/V0 over every step, per constrained body of ``case`` and overall.

    Returns a dict: ``volume_error`` (the largest of all) and ``bodies`` (name: largest).
    """
    bodies = {}
    for k, body in enumerate(case["body"]):
        name = body["name"] or f"body{k}"
        bodies[name] = float(np.abs(solid_series(path, name)["volume_error"]).max())
    return {"volume_error": max(bodies.values()) if bodies else 0.0, "bodies": bodies}


def lattice_bend(nodes, body):
    """How far a lattice body's middle row runs ahead of its end rows along -x.

    ``nodes`` are the body's node positions (node i + nx j, row by row from below);
    > 0 for a body bent into a cup open towards +x (the box in flow's parachute).
    """
    nx, ny = body["nx"], body["ny"]
    x = nodes[:nx * ny, 0].reshape(ny, nx)
    return -(x[ny // 2].mean() - 0.5 * (x[0].mean() + x[-1].mean()))


def lattice_top_middle(body):
    """Index of a lattice body's top-row middle node (node i + nx j, row by row from below)."""
    return body["nx"] * (body["ny"] - 1) + body["nx"] // 2


def tip_trajectory(path, case):
    """Time and y of the first body's top-row middle node, frame by frame."""
    body = case["body"][0]
    name, node = body["name"] or "body0", lattice_top_middle(body)
    with open_result(path) as result:
        ys = [frame.bodies[name]["position"][node, 1] for frame in result.frames]
        return result.frames.times, np.array(ys)


def sag_series(path, body, nodes, rest):
    """The frames' times and the mean downward displacement (along the last axis, which
    gravity points down) of the body's ``nodes`` from their ``rest`` positions in each."""
    with open_result(path) as result:
        times = result.frames.times
        sag = np.array([-float(np.mean(frame.bodies[body]["position"][nodes, -1]
                                       - rest[nodes, -1])) for frame in result.frames])
    return times, sag


def clamped_plate_deflection(path, case, settle_time, body="plate"):
    """Time-averaged mid-span deflection of a plate clamped at both ends under a water
    column, against Euler-Bernoulli: w = q L^4 / (384 D), q = g (rho_f h + rho_s t).

    Everything comes from ``case``: the plate is the lattice body named ``body``
    (thickness t = (ny - 1) spacing, the rectangle between its outer nodes; E, nu, plane
    and rho_s of its material, D = E2 t^3/12 with E2 = E/(1 - nu^2) in plane strain); its
    span L lies between the innermost pinned columns on either side of its middle; the
    water depth h is the fluid blocks' height; rho_f and g from the case. The deflection is
    the mean downward displacement of the mid-span column of nodes, frame by frame,
    averaged over the frames from ``settle_time`` on. Returns a dict: ``deflection``,
    ``expected``, ``error`` (relative), ``amplitude`` (half the range of the averaged
    frames), ``span``, ``load`` (q), ``bending_stiffness`` (D) and the series ``time`` and
    ``series``.
    """
    from parmps.solids.mass_spring.build import lattice_geometry, node_set
    from parmps.solids.mass_spring.elastic import plane_modulus, REPRESENTABLE_POISSON

    (spec,) = [b for k, b in enumerate(case["body"]) if (b["name"] or f"body{k}") == body]
    nx, ny, spacing = spec["nx"], spec["ny"], spec["spacing"]
    rest, _, _, _ = lattice_geometry((nx, ny), spacing, spec["lower"])
    pinned = np.zeros(len(rest), bool)
    if spec["pinned"] != "none":
        pinned[node_set(body, spec["pinned"], rest, shape=(nx, ny))] = True
    if spec["pinned_ids"]:
        pinned[node_set(body, "ids", rest, ids=spec["pinned_ids"])] = True
    x = rest[:, 0]
    middle = 0.5 * (x.min() + x.max())
    left, right = x[pinned & (x < middle)], x[pinned & (x > middle)]
    if not len(left) or not len(right):
        raise ValueError(f"body '{body}' is not pinned on both sides of its middle")
    clamp_left, clamp_right = left.max(), right.min()
    span = clamp_right - clamp_left
    centre = 0.5 * (clamp_left + clamp_right)
    column = np.flatnonzero(np.isclose(x, x[np.argmin(np.abs(x - centre))]))
    thickness = (ny - 1) * spacing
    poisson = spec["poisson_ratio"]
    if poisson is None:
        poisson = REPRESENTABLE_POISSON[spec["plane"]]
    modulus, _ = plane_modulus(spec["youngs_modulus"], poisson, spec["plane"])
    bending = modulus * thickness ** 3 / 12.0
    lower, upper = fluid_extent(case)
    g = gravity(case)
    load = g * (case["fluid"]["density"] * (upper[1] - lower[1]) + spec["density"] * thickness)
    expected = load * span ** 4 / (384.0 * bending)
    times, deflection = sag_series(path, body, column, rest)
    mean = window_mean(times, deflection, settle_time, times[-1])
    settled = deflection[times >= settle_time]
    return {"deflection": mean, "expected": float(expected),
            "error": float(mean / expected - 1.0),
            "amplitude": float(0.5 * np.ptp(settled)) if len(settled) else math.nan,
            "span": float(span), "load": float(load), "bending_stiffness": float(bending),
            "time": times, "series": deflection}


def clamped_square_plate_deflection(path, case, settle_time, body="plate"):
    """Time-averaged centre deflection of a square plate clamped on its four edges under a
    water layer, against Kirchhoff: w = 0.00126 q a^4 / D, q = g (rho_f h + rho_s t),
    D = E t^3 / 12 (1 - nu^2) with the 3D lattice's nu = 1/4 (the only one it represents).

    Everything comes from ``case``: the plate is the 3D lattice body named ``body``
    (thickness t = (nz - 1) spacing between its outer layers); its free nodes are those not
    pinned (``pinned``, ``pinned_ids``, ``pinned_outside``), and it is clamped one spacing
    beyond them on each side, so a = the free nodes' extent + 2 spacings, the same along x
    and y; the water depth h is the fluid blocks' height. The deflection is the mean
    downward displacement of the nodes through the thickness at the centre, frame by frame,
    averaged over the whole periods of its swing that fit after ``settle_time``
    (:func:`whole_period_mean`). Returns ``deflection``, ``expected``, ``error``,
    ``amplitude`` (half the range from ``settle_time`` on), ``period``, ``periods``,
    ``span``, ``load``, ``bending_stiffness``, ``time`` and ``series``.
    """
    from parmps.solids.mass_spring.build import lattice_geometry, pinned_nodes
    from parmps.solids.mass_spring.elastic import LATTICE_POISSON_3D
    from parmps.tools.elastic_3d import KIRCHHOFF_CLAMPED_SQUARE

    (spec,) = [b for k, b in enumerate(case["body"]) if (b["name"] or f"body{k}") == body]
    shape, spacing = (spec["nx"], spec["ny"], spec["nz"]), spec["spacing"]
    rest = lattice_geometry(shape, spacing, spec["lower"])[0]
    free = rest[~pinned_nodes(body, spec, rest, shape)]
    spans = np.ptp(free[:, :2], axis=0) + 2.0 * spacing
    if not len(free) or not np.isclose(spans[0], spans[1]):
        raise ValueError(f"body '{body}' is not a square plate clamped on four edges "
                         f"(free spans {spans})")
    centre = free[:, :2].min(axis=0) + 0.5 * (spans - 2.0 * spacing)
    offset = np.linalg.norm(rest[:, :2] - centre, axis=1)
    column = np.flatnonzero(np.isclose(offset, offset.min(), atol=1e-9 * spacing))
    thickness = (shape[2] - 1) * spacing
    bending = spec["youngs_modulus"] * thickness ** 3 / (12.0 * (1.0 - LATTICE_POISSON_3D ** 2))
    lower, upper = fluid_extent(case)
    load = gravity(case) * (case["fluid"]["density"] * (upper[2] - lower[2])
                            + spec["density"] * thickness)
    expected = KIRCHHOFF_CLAMPED_SQUARE * load * spans[0] ** 4 / bending
    times, deflection = sag_series(path, body, column, rest)
    mean, period, periods = whole_period_mean(times, deflection, settle_time, times[-1])
    settled = deflection[times >= settle_time]
    return {"deflection": mean, "expected": float(expected),
            "error": float(mean / expected - 1.0),
            "amplitude": float(0.5 * np.ptp(settled)) if len(settled) else math.nan,
            "period": period, "periods": periods,
            "span": float(spans[0]), "load": float(load), "bending_stiffness": float(bending),
            "time": times, "series": deflection}


def whole_period_mean(times, series, start, end):
    """The mean of an oscillating series over the whole periods that fit in [start, end],
    the last ones before ``end`` (the linear interpolant between samples, integrated
    exactly): a suddenly loaded plate swings about its equilibrium with little damping,
    and a window of 2.8 periods moves a plain mean by several percent. Returns (mean,
    period, periods); with less than one period in the window (or none found), the plain
    mean over [start, end], NaN and 0; NaN, NaN and 0 with fewer than two samples in it."""
    window = (times >= start) & (times <= end)
    if np.count_nonzero(window) < 2:
        return math.nan, math.nan, 0
    period = crossing_period(times[window], series[window])
    periods = int((end - start) // period) if np.isfinite(period) else 0
    if periods:
        start = end - periods * period
    inner = (times > start) & (times < end)
    t = np.concatenate([[start], times[inner], [end]])
    value = np.interp(t, times, series)
    mean = float(np.sum(0.5 * (value[1:] + value[:-1]) * np.diff(t)) / (end - start))
    return mean, (float(period) if periods else math.nan), periods


def crossing_period(times, series):
    """The period of an oscillating series: a straight line through the times it crosses its
    mean (interpolated), so no single crossing sets it. NaN with fewer than three."""
    value = np.asarray(series) - np.mean(series)
    sign = np.signbit(value)
    k = np.flatnonzero(sign[1:] != sign[:-1])
    if len(k) < 3:
        return math.nan
    crossings = times[k] + (times[k + 1] - times[k]) * value[k] / (value[k] - value[k + 1])
    return 2.0 * float(np.polyfit(np.arange(len(crossings)), crossings, 1)[0])


def cantilever_period(path, case, body="beam", settle_time=0.0):
    """A clamped lattice cantilever swinging (validation/cantilever_3d/): the period of its
    free end's deflection against Euler-Bernoulli's 2 pi/omega_1,
    omega_1 = 1.8751^2 sqrt(E I/(rho A L^4)).

    From ``case``: the lattice body named ``body`` lies along x, clamped at its left end,
    and bends along the last axis; L and the depth h are the distances between its outer
    nodes along x and along the last axis; its width b is (ny - 1) spacing in 3D (E the
    material's) and ``thickness`` in 2D (E2 = E/(1 - nu^2) in plane strain, nu the
    lattice's). The deflection is the mean displacement of the right end's nodes along
    the last axis, from ``settle_time`` on. Returns ``period``, ``expected``, ``error``
    (relative), ``mean_deflection`` and the series ``time`` and ``series``.
    """
    from parmps.solids.mass_spring.elastic import REPRESENTABLE_POISSON, plane_modulus
    from parmps.tools.cantilever import FIRST_ROOT

    (spec,) = [b for k, b in enumerate(case["body"]) if (b["name"] or f"body{k}") == body]
    shape = [spec["nx"], spec["ny"]] + ([spec["nz"]] if spec.get("nz") else [])
    spacing = spec["spacing"]
    length, depth = (shape[0] - 1) * spacing, (shape[-1] - 1) * spacing
    if len(shape) == 3:
        width, modulus = (shape[1] - 1) * spacing, spec["youngs_modulus"]
    else:
        poisson = spec["poisson_ratio"]
        if poisson is None:
            poisson = REPRESENTABLE_POISSON[spec["plane"]]
        width = spec["thickness"]
        modulus, _ = plane_modulus(spec["youngs_modulus"], poisson, spec["plane"])
    bending = modulus * width * depth ** 3 / 12.0
    line_mass = spec["density"] * width * depth
    omega = FIRST_ROOT ** 2 * math.sqrt(bending / (line_mass * length ** 4))
    with open_result(path) as result:
        times = np.asarray(result.frames.times)
        rest = result.frames[0].bodies[body]["position"]
        tip = np.isclose(rest[:, 0], rest[:, 0].max())
        deflection = np.array([float(np.mean(frame.bodies[body]["position"][tip, -1]
                                             - rest[tip, -1])) for frame in result.frames])
    later = times >= settle_time
    period = crossing_period(times[later], deflection[later])
    expected = 2.0 * math.pi / omega
    return {"period": period, "expected": expected, "error": period / expected - 1.0,
            "mean_deflection": float(np.mean(deflection[later])), "time": times,
            "series": deflection}


def kirchhoff_plate(path, case, body="plate"):
    """The clamped square plate of validation/kirchhoff_plate/ against Kirchhoff's centre
    deflection 0.00126 q a^4/D, D = E t^3/12(1 - nu^2) with the lattice's nu = 1/4.

    A static figure: the linear statics of the plate ``case`` describes (the lattice body
    named ``body``, n x n x nt nodes, pinned on its four side faces, its one load on its top
    nodes a pressure q = -force_z / spacing^2), solved on a quadrant
    (parmps.tools.elastic_3d.clamped_plate_deflection); the run's frames are not read.
    Returns ``deflection``, ``expected``, ``error``, ``side``, ``thickness``, ``nodes``.
    """
    from parmps.solids.mass_spring.build import node_set
    from parmps.tools import elastic_3d

    (spec,) = [b for k, b in enumerate(case["body"]) if (b["name"] or f"body{k}") == body]
    shape, spacing = (spec["nx"], spec["ny"], spec["nz"]), spec["spacing"]
    position = spacing * np.indices(shape[::-1]).reshape(3, -1)[::-1].T
    index = np.rint(position / spacing).astype(int)
    sides = ((index[:, :2] == 0) | (index[:, :2] == np.array(shape[:2]) - 1)).any(axis=1)
    pinned = np.zeros(len(position), bool)
    pinned[node_set(body, "ids", position, ids=spec["pinned_ids"])] = True
    (load,) = spec["load"]
    if shape[0] != shape[1] or shape[0] % 2 == 0 or not np.array_equal(pinned, sides) \
            or load["nodes"] != "top":
        raise ValueError(f"body '{body}' is not a square plate (odd n) clamped on its four "
                         f"side faces under a load on its top nodes")
    pressure = -load["force"][2] / spacing ** 2
    return elastic_3d.clamped_plate_deflection(shape, spacing, spec, pressure)


def elastic_gate(path, case, probe="gate_tip", check="gate_crossing", body="gate",
                 references=None):
    """The elastic gate's run (validation/elastic_gate/): its free end's displacement from
    the displacement probe, the fluid crossings of the body_crossing check, the body's
    largest area error and how far the run got.

    ``references``: component ("dx", "dy") -> CSV of the measured (t, displacement); each
    gives ``<component>_peak_error`` (the run's largest value against the record's, relative
    to the record's) and ``<component>_rms_error`` (the RMS difference at the record's times
    that the run reached, relative to the record's peak).

    Returns a dict: time, dx, dy (the tip series: dx along the flow, dy the vertical, the
    last axis), dx_max and t_dx_max (the largest
    horizontal opening and when), dy_max (the largest rise), crossings (their total),
    volume_error (largest |A - A0|/A0), end (the last step's time) and the errors above.
    """
    time, value = read_probe(path, probe)
    with open_result(path) as result:
        total = result.checks[check]["total"]
        end = float(result.diagnostics["time"][-1])
    error = float(np.abs(solid_series(path, body)["volume_error"]).max())
    peak = int(np.argmax(value[:, 0]))
    # dx along the flow, dy the vertical: the last axis (z in 3D).
    measured = {"time": time, "dx": value[:, 0], "dy": value[:, -1],
                "dx_max": float(value[peak, 0]), "t_dx_max": float(time[peak]),
                "dy_max": float(value[:, -1].max()),
                "crossings": int(total[-1]) if len(total) else 0,
                "volume_error": error, "end": end}
    for component, reference in (references or {}).items():
        t_ref, v_ref = list(reference_table(reference).values())[:2]
        peak_error, rms_error = curve_errors(time, measured[component], t_ref, v_ref)
        measured[f"{component}_peak_error"] = peak_error
        measured[f"{component}_rms_error"] = rms_error
    return measured


def curve_errors(time, value, t_ref, v_ref):
    """A simulated series against a measured one: (the series' largest value over the
    record's largest, less 1; the RMS difference at the record's times the series reached,
    interpolated linearly, over the record's largest)."""
    reached = t_ref <= time[-1]
    scale = float(np.max(v_ref))
    simulated = np.interp(t_ref[reached], time, value)
    return (float(np.max(value) / scale - 1.0),
            float(np.sqrt(np.mean((simulated - v_ref[reached]) ** 2)) / scale))


def carried_body(path, case, body="box", check=None):
    """A body carried by an inflow or a periodic duct's body force (validation/box_in_flow_3d/,
    capsule_3d/, capsule_periodic_3d/), in any dimension: its largest |V - V0|/V0, the most fluid particles inside it at any step and
    how much that count changed (a shell holds its water: any change is a leak), how far its
    centroid travelled along the first inlet's velocity (or the body force: the flow's direction) by the last
    step and across it, how far the run got and, with ``check`` (a body_crossing check's
    name), the fluid particles that crossed the body.

    Returns a dict: volume_error, fluid_inside, fluid_inside_change, held_back (the
    particles a closed shell held to their side over the run), carried [m], across [m],
    end [s], steps (and crossings).
    """
    series = solid_series(path, body)
    centroid = np.asarray(series["centroid"])
    # The flow's direction: the first inlet's, or in a periodic duct the driving body force's.
    flow = np.asarray(case["inlet"][0]["velocity"] if case["inlet"]
                      else case["physics"]["gravity"], dtype=float)
    flow /= np.linalg.norm(flow)
    travel = centroid[-1] - centroid[0]
    along = float(travel @ flow)
    with open_result(path) as result:
        time = result.diagnostics["time"]
        total = result.checks[check]["total"] if check else None
    measured = {"volume_error": float(np.abs(series["volume_error"]).max()),
                "fluid_inside": int(np.max(series["fluid_inside"])),
                "fluid_inside_change": int(np.ptp(series["fluid_inside"])),
                "held_back": int(np.sum(series["held_back"])) if "held_back" in series else 0,
                "carried": along, "across": float(np.linalg.norm(travel - along * flow)),
                "end": float(time[-1]), "steps": int(len(time))}
    if check:
        measured["crossings"] = int(total[-1]) if len(total) else 0
    return measured


def lattice_area(body):
    """Area [m^2 per unit depth] of the fluid a lattice body displaces: one l0^2 per node."""
    return body["nx"] * body["ny"] * body["spacing"] ** 2


def buoyancy_error(path, case, settle_time):
    """The fluid force on the first body against rho g V (Archimedes), and its drift.

    V is the area of the particles the body displaces; density and gravity come from
    ``case``. Returns a dict: ``force`` and ``force_x``, the vertical force's relative
    error and the horizontal force relative to rho g V, both averaged over the steps
    after ``settle_time``; ``drift``, the centroid's largest travel in units of l0;
    ``volume_error``, the largest |V - V0|/V0.
    """
    body = case["body"][0]
    series = solid_series(path, body["name"] or "body0")
    expected = case["fluid"]["density"] * gravity(case) * lattice_area(body)
    settled = series["time"] > settle_time
    force = series["fluid_force"][settled].mean(axis=0)
    travel = series["centroid"] - series["centroid"][0]
    return {"force": float(force[1] / expected - 1.0), "force_x": float(abs(force[0]) / expected),
            "expected_force": float(expected),
            "drift": float(np.hypot(*travel.T).max() / case["particles"]["spacing"]),
            "volume_error": float(np.abs(series["volume_error"]).max())}


def inflow_rate(case):
    """Particles per second the first inlet of ``case`` lets in: |U0| x its width / l0^2."""
    inlet = case["inlet"][0]
    along = int(np.argmax(np.abs(inlet["velocity"])))
    width = inlet["upper"][1 - along] - inlet["lower"][1 - along]
    return float(np.hypot(*inlet["velocity"]) * width / case["particles"]["spacing"] ** 2)


# --------------------------------------------------------------------------
# Probes

def read_probe(path, name):
    """(time, value) of the probe ``name`` in a result file; ``value`` in SI units."""
    with open_result(path) as result:
        return result.probes[name]["time"], result.probes[name]["value"]


def window_mean(t, value, start, end):
    """Time average of a sampled series over [start, end] (trapezoids over its samples,
    NaN samples left out); NaN when fewer than two samples fall in the window."""
    keep = (t >= start) & (t <= end) & np.isfinite(value)
    if np.count_nonzero(keep) < 2:
        return math.nan
    t, value = t[keep], value[keep]
    return float(np.sum(0.5 * (value[1:] + value[:-1]) * np.diff(t)) / (t[-1] - t[0]))


def running_mean(t, value, width):
    """The centred time average of a sampled series over a window ``width`` long, at each
    sample (trapezoids; a NaN sample counts as 0, as a dry wall carries no load). Near
    the ends the window is cut to the series."""
    t = np.asarray(t, float)
    value = np.nan_to_num(np.asarray(value, float), nan=0.0)
    integral = np.concatenate([[0.0], np.cumsum(0.5 * (value[1:] + value[:-1]) * np.diff(t))])
    start = np.maximum(t - 0.5 * width, t[0])
    end = np.minimum(t + 0.5 * width, t[-1])
    span = end - start
    inside = np.interp(end, t, integral) - np.interp(start, t, integral)
    return np.where(span > 0, inside / np.where(span > 0, span, 1.0), value)


def first_crossing(t, value, threshold):
    """The first time ``value`` exceeds ``threshold``; NaN if it never does."""
    above = np.flatnonzero(np.nan_to_num(value, nan=-np.inf) > threshold)
    return float(t[above[0]]) if len(above) else math.nan


def impact_pressure_metrics(path, case, references, arrival_threshold=0.2,
                            mean_window=(3.0, 6.0), peak_until=6.0):
    """Wall pressure probes of a dam break against measured records, in the experiment's
    scales: t* = t sqrt(g/H), p* = p / (rho g H), H the column's height from ``case``.

    ``references``: probe name -> CSV of (t*, p*). Per probe: ``arrival`` (the first t*
    with p* > ``arrival_threshold``), ``mean`` (the time average over ``mean_window`` in t*)
    and ``peak`` (the largest p* for t* <= ``peak_until`` and its t*), each simulated and
    measured, with the arrival's difference and the mean's relative difference.
    """
    lower, upper = fluid_extent(case)
    height = upper[1] - lower[1]
    g = gravity(case)
    time_scale = column_time_scale(case)
    pressure_scale = case["fluid"]["density"] * g * height
    out = {}
    for name, reference in references.items():
        t, p = read_probe(path, name)
        t, p = t * time_scale, p / pressure_scale
        te, pe = list(reference_table(reference).values())[:2]
        finite = np.isfinite(p) & (t <= peak_until)
        peak = int(np.argmax(np.where(finite, p, -np.inf))) if finite.any() else 0
        measured_peak = int(np.argmax(np.where(te <= peak_until, pe, -np.inf)))
        row = {"arrival": first_crossing(t, p, arrival_threshold),
               "arrival_measured": first_crossing(te, pe, arrival_threshold),
               "mean": window_mean(t, p, *mean_window),
               "mean_measured": window_mean(te, pe, *mean_window),
               "peak": float(p[peak]) if finite.any() else math.nan,
               "peak_time": float(t[peak]) if finite.any() else math.nan,
               "peak_measured": float(pe[measured_peak]),
               "peak_time_measured": float(te[measured_peak]),
               "nan_fraction": float(np.mean(~np.isfinite(p)))}
        row["arrival_error"] = row["arrival"] - row["arrival_measured"]
        row["mean_error"] = row["mean"] / row["mean_measured"] - 1.0
        out[name] = row
    return out


def level_metrics(path, record, windows, wet_depth, record_origin=0.0):
    """Level probes against a record of the same gauges (``record``: time first, then a
    column per gauge [m]): per gauge, the first time deeper than ``wet_depth`` and the mean
    depth over each of its ``windows``, simulated and measured. The record's times are
    read ``record_origin`` [s] later (its clock against the release:
    :func:`sensor_pressure_metrics`); ``wet_measured_raw`` and ``mean_measured_raw`` are
    the record's own clock's."""
    raw = list(record.values())[0]
    te = raw + record_origin
    out = {}
    for name, spans in windows.items():
        t, depth = read_probe(path, name)
        depth = np.asarray(depth, float).ravel()
        out[name] = {"wet": first_crossing(t, depth, wet_depth),
                     "wet_measured": first_crossing(te, record[name], wet_depth),
                     "wet_measured_raw": first_crossing(raw, record[name], wet_depth),
                     "means": [{"window": [start, end],
                                "mean": window_mean(t, depth, start, end),
                                "mean_measured": window_mean(te, record[name], start, end),
                                "mean_measured_raw": window_mean(raw, record[name], start, end)}
                               for start, end in spans]}
    return out


def sensor_pressure_metrics(path, case, reference, windows, arrival_threshold=500.0,
                            peak_width=0.01, peak_until=None, arrival_sensors=(),
                            level_reference=None, level_windows=None, wet_depth=0.02,
                            record_origin=0.0):
    """Pressure probes against a record of the same sensors in SI units (SPHERIC Test 2).

    ``reference``: a CSV whose first column is the time [s] and whose others are named
    after the probes (gauge pressure [Pa]). ``windows``: probe name -> list of
    ``[start, end]`` [s] over which the time-averaged pressure is compared. Per probe:
    ``arrival`` (the first time above ``arrival_threshold`` [Pa]) for ``arrival_sensors``,
    ``means`` (simulated, measured, relative difference per window) and ``peak``: the
    largest ``peak_width``-second running mean up to ``peak_until`` (default the run's
    end), with its time, beside the record's.

    ``record_origin`` [s]: how long after an instant release the record's clock reads 0,
    one constant for every sensor and gauge; the record's sample at ``t`` is compared with
    the run's at ``t + record_origin``. The measured figures and the errors are on that
    clock; each has its record's own clock's beside it (``..._raw``). ``record_origin_ms``
    says which was used.

    With ``level_reference`` (a CSV of the same record's water depths, its columns named
    after the level probes) and ``level_windows`` (gauge name -> windows): per gauge, its
    ``wet`` time (the first depth above ``wet_depth`` [m]) and mean depth per window,
    simulated beside measured. Reported, not judged: the record's gauges read a few
    millimetres off before the release.
    """
    table = reference_table(reference)
    raw = list(table.values())[0]
    te = raw + record_origin
    out = {"record_origin_ms": 1000.0 * record_origin}
    if level_reference is not None and level_windows:
        out["levels"] = level_metrics(path, reference_table(level_reference), level_windows,
                                      wet_depth, record_origin)
    for name, spans in windows.items():
        t, p = read_probe(path, name)
        pe = table[name]
        until = t[-1] if peak_until is None else peak_until
        smooth, smooth_e = running_mean(t, p, peak_width), running_mean(te, pe, peak_width)
        k = int(np.argmax(np.where(t <= until, smooth, -np.inf)))
        ke = int(np.argmax(np.where(te <= until, smooth_e, -np.inf)))
        row = {"peak": float(smooth[k]), "peak_time": float(t[k]),
               "peak_measured": float(smooth_e[ke]), "peak_time_measured": float(te[ke]),
               "peak_time_measured_raw": float(raw[ke]),
               "nan_fraction": float(np.mean(~np.isfinite(p))), "means": []}
        for start, end in spans:
            # Dry samples carry no load on a wall: a NaN reading counts as 0 Pa.
            mean = window_mean(t, np.nan_to_num(p, nan=0.0), start, end)
            measured = window_mean(te, pe, start, end)
            measured_raw = window_mean(raw, pe, start, end)
            row["means"].append({"window": [start, end], "mean": mean,
                                 "mean_measured": measured, "error": mean / measured - 1.0,
                                 "mean_measured_raw": measured_raw,
                                 "error_raw": mean / measured_raw - 1.0})
        if name in arrival_sensors:
            row["arrival"] = first_crossing(t, p, arrival_threshold)
            row["arrival_measured"] = first_crossing(te, pe, arrival_threshold)
            row["arrival_error"] = row["arrival"] - row["arrival_measured"]
            row["arrival_measured_raw"] = first_crossing(raw, pe, arrival_threshold)
            row["arrival_error_raw"] = row["arrival"] - row["arrival_measured_raw"]
        out[name] = row
    return out


# --------------------------------------------------------------------------
# SPHERIC Test 2: the record's clock against an instant release

def dam_break_surface_acceleration(x, depth, length, g, terms=400):
    """The free surface's vertical acceleration [m/s^2] at the instant a door is removed from
    a 2D column at rest, ``depth`` deep and ``length`` long against a wall, at distances
    ``x`` [m] behind the door (0 <= x <= length): the potential-flow start, negative where the
    surface falls.

    The pressure at the first instant is harmonic, zero on the top and on the door's face,
    with no normal acceleration on the floor and the wall; its series gives
    ``a(x) = -g (4/pi) sum_n (-1)^n/(2n+1) cosh(k_n (length - x)) / cosh(k_n length)``,
    ``k_n = (2n+1) pi / (2 depth)``: -g at the door, about -(4/pi) g exp(-pi x / (2 depth))
    beyond a depth. The derivation: docs/validation/dam_break_3d.md.
    """
    x = np.asarray(x, float)
    n = np.arange(terms)
    k = (2 * n + 1) * np.pi / (2.0 * depth)
    sign = np.where(n % 2 == 0, 1.0, -1.0) / (2 * n + 1)
    xs = x[..., None]
    # cosh(k (L - x)) / cosh(k L) without overflow
    ratio = (np.exp(-k * xs) + np.exp(-k * (2.0 * length - xs))) / (1.0 + np.exp(-2.0 * k * length))
    return -g * 4.0 / np.pi * np.sum(sign * ratio, axis=-1)


def incompressible_start_level(t, x, depth, length, g):
    """The water's depth [m] at times ``t`` [s] after an instant release, at ``x`` [m] behind
    the door, to the first order of the small-time expansion: ``depth + a(x) t^2 / 2``
    (:func:`dam_break_surface_acceleration`; ``depth`` before the release). Valid while the
    surface has moved little against the depth (some 10 mm at 0.65 m behind a 0.55 m door)."""
    t = np.asarray(t, float)
    a = float(dam_break_surface_acceleration(x, depth, length, g))
    return depth + 0.5 * a * np.where(t > 0, t, 0.0) ** 2


def record_delay(t_record, record, t_model, model, window, baseline=None, offsets=None):
    """The offset [s] between a record's clock and a model's of the same gauge: the record's
    sample at ``t`` is the model's at ``t + delay`` (a positive delay: the record's clock
    started after the model's release), fitted by least squares over the record's samples
    in ``window`` = (start, end) [s]. ``baseline`` [m]: the record's reading less the
    model's where both are right, a constant; None fits it beside the delay (over a short
    window the two trade against each other: a falling curve shifted in time looks much
    like one shifted in height).

    The model is read by linear interpolation, at its first value before its first sample
    (at rest). ``offsets``: the delays tried [s] (default -0.1 to 0.2 s by 0.5 ms); the best
    is refined by a parabola through its neighbours. Returns ``delay``, ``baseline``, ``rms``
    (the residual [m]), ``stderr`` (the delay's standard error from the residual, widened
    for the residual's correlation from sample to sample) and ``samples``.
    """
    t_record, record = np.asarray(t_record, float), np.asarray(record, float).ravel()
    t_model, model = np.asarray(t_model, float), np.asarray(model, float).ravel()
    keep = (t_record >= window[0]) & (t_record <= window[1]) & np.isfinite(record)
    t, y = t_record[keep], record[keep]
    if len(t) < 4:
        raise ValueError(f"record_delay: {len(t)} samples in the window {window}")
    offsets = np.arange(-0.1, 0.2 + 1e-9, 5e-4) if offsets is None else np.asarray(offsets)

    fixed = baseline

    def fit(delay):
        shifted = np.interp(t + delay, t_model, model, left=model[0])
        offset = float(np.mean(y - shifted)) if fixed is None else float(fixed)
        residual = y - shifted - offset
        return float(np.sum(residual ** 2)), offset, residual

    cost = np.array([fit(d)[0] for d in offsets])
    k = int(np.argmin(cost))
    delay = float(offsets[k])
    if 0 < k < len(offsets) - 1:
        c0, c1, c2 = cost[k - 1], cost[k], cost[k + 1]
        curvature = c0 - 2 * c1 + c2
        if curvature > 0:
            delay += 0.5 * (c0 - c2) / curvature * (offsets[k + 1] - offsets[k])
    ssr, baseline, residual = fit(delay)
    h = 1e-3
    slope = (np.interp(t + delay + h, t_model, model, left=model[0])
             - np.interp(t + delay - h, t_model, model, left=model[0])) / (2 * h)
    if fixed is None:
        slope = slope - slope.mean()  # the baseline is fitted beside the delay
    dof = max(len(t) - (2 if fixed is None else 1), 1)
    variance = ssr / dof / max(float(np.sum(slope ** 2)), 1e-30)
    rho = float(np.corrcoef(residual[:-1], residual[1:])[0, 1]) if len(t) > 4 else 0.0
    rho = min(max(rho, 0.0), 0.95) if np.isfinite(rho) else 0.0
    return {"delay": delay, "baseline": baseline, "rms": math.sqrt(ssr / len(t)),
            "stderr": math.sqrt(variance * (1 + rho) / (1 - rho)), "samples": int(len(t)),
            "window": [float(window[0]), float(window[1])]}


def gauge_x(case, name):
    """The x [m] of a level probe's line in a case (its first point's)."""
    for probe in case["probe"]:
        if probe["name"] == name:
            return float(probe["line"][0][0])
    raise KeyError(f"the case has no level probe '{name}'")


def record_origin_fits(record, results=(), gauges=("H4",), window=(0.0, 0.35),
                       theory_window=(0.0, 0.05), case=None):
    """The record's clock against an instant release, from its level gauges (SPHERIC Test 2):
    :func:`record_delay` of each of ``gauges`` of ``record`` (a level record as
    :func:`reference_table` reads it) against the same gauge of each result file in
    ``results`` over ``window`` [s], and of the first gauge against the incompressible start
    (:func:`incompressible_start_level`) over ``theory_window``.

    The record's gauge is taken to read the column's depth at rest, or zero outside the
    column (the baseline fixed: the run's reading at rest, its first sample, stands for
    that). The door is the fluid
    block's face away from the tank's far wall: the lower x of the one fluid block; ``case``
    (default the first result's) gives it, the depth and each gauge's x. Returns one row per
    fit: ``source`` (the result's path or "incompressible start"), ``spacing``, ``gauge`` and
    :func:`record_delay`'s figures.
    """
    rows = []
    for path in results:
        run_case = result_case(path)
        case = case or run_case
        lower, upper = fluid_extent(run_case)
        depth = float(upper[-1] - lower[-1])
        for name in gauges:
            t, level = read_probe(path, name)
            level = np.asarray(level, float).ravel()
            inside = lower[0] <= gauge_x(run_case, name) <= upper[0]
            fit = record_delay(record["t"], record[name], t, level, window,
                               baseline=(depth if inside else 0.0) - level[0])
            rows.append({"source": str(path), "spacing": run_case["particles"]["spacing"],
                         "gauge": name, **fit})
    if case is None:
        raise ValueError("record_origin_fits: give a case or at least one result")
    lower, upper = fluid_extent(case)
    depth, length = float(upper[-1] - lower[-1]), float(upper[0] - lower[0])
    inside = [name for name in gauges if lower[0] < gauge_x(case, name) <= upper[0]]
    if not inside:
        return rows
    name = inside[0]
    x = gauge_x(case, name) - float(lower[0])
    t = np.linspace(0.0, theory_window[1] + 0.3, 4001)
    level = incompressible_start_level(t, x, depth, length, gravity(case))
    fit = record_delay(record["t"], record[name], t, level, theory_window, baseline=0.0)
    rows.append({"source": "incompressible start", "spacing": 0.0, "gauge": name,
                 "acceleration": float(dam_break_surface_acceleration(x, depth, length,
                                                                      gravity(case))),
                 **fit})
    return rows

# A cell stretched by optical tweezers (validation/rbc_stretch/)

def _pull_levels(spec):
    """(start times, total pull at each level [N]) of a body's loads along +x: each load
    adds its total force from its start on (the staircase of validation/rbc_stretch/)."""
    pulls = sorted((load for load in spec["load"] if load["force"][0] > 0),
                   key=lambda load: load["start"])
    if not pulls or not all(load["total"] for load in pulls):
        raise ValueError("the body has no pull along +x given as a total (total = true)")
    starts = np.array([load["start"] for load in pulls])
    return starts, np.cumsum([load["force"][0] for load in pulls])


def _diameters(position):
    """(axial, transverse) extent of a cell: along x, and along y in the disc's plane."""
    return float(np.ptp(position[:, 0])), float(np.ptp(position[:, 1]))


def cell_stretch(path, case, reference, body="cell", drift_window=5.0e-4):
    """The stretched cell's axial and transverse diameters at every pull, at the end of
    its hold, against the experiment's range (``reference``: force_pN and the low/high
    columns of each diameter), with how still the cell was there.

    The pull is the body's loads along +x (:func:`_pull_levels`); each level is held until
    the next one starts, or the run ends. At rest means: the fastest node's speed in the
    hold's last frame, and the diameters' change over its last ``drift_window`` seconds.
    Returns ``forces`` (per level, keyed by its force in pN, 0 first: force_pN, axial_um
    and transverse_um, their ranges and verdicts, speed [m/s], drift [m], wall [s]), the
    counts outside the ranges, the largest speed and drift [m], the largest area and
    volume errors, and the loop's wall seconds in all.
    """
    (spec,) = [b for k, b in enumerate(case["body"]) if (b["name"] or f"body{k}") == body]
    starts, levels = _pull_levels(spec)
    table = reference_table(reference)
    series = solid_series(path, body)
    with open_result(path) as result:
        times = np.asarray(result.frames.times)
        wall, steps = result.diagnostics["wall_seconds"], result.diagnostics["time"]
        ends = np.append(starts[1:], times[-1])
        # (force, end of its hold, its last frame, the frame drift_window before).
        samples = [(0.0, 0.0, 0, 0)] + [
            (force, end, int(np.searchsorted(times, end + 1e-12) - 1),
             int(np.searchsorted(times, end - drift_window + 1e-12) - 1))
            for force, end in zip(levels, ends)]
        frames = {k: {key: np.array(result.frames[k].bodies[body][key])
                      for key in ("position", "velocity")} for s in samples for k in s[2:]}
    forces = []
    for level, (force, end, last, before) in enumerate(samples):
        row = int(np.argmin(np.abs(table["force_pN"] - force * 1e12)))
        if abs(table["force_pN"][row] - force * 1e12) > 0.5:
            raise ValueError(f"no reference row for {force * 1e12:.1f} pN")
        axial, transverse = _diameters(frames[last]["position"])
        drift = np.subtract(_diameters(frames[last]["position"]),
                            _diameters(frames[before]["position"]))
        start = starts[level - 1] if level else 0.0
        spent = (float(np.interp(end, steps, wall) - np.interp(start, steps, wall))
                 if level else 0.0)
        entry = {"force_pN": float(table["force_pN"][row]), "axial_um": axial * 1e6,
                 "transverse_um": transverse * 1e6,
                 "speed": float(np.linalg.norm(frames[last]["velocity"], axis=1).max()),
                 "drift": float(np.abs(drift).max()), "wall": spent}
        for name in ("axial", "transverse"):
            low, high = (float(table[f"{name}_{end}_um"][row]) for end in ("low", "high"))
            entry.update({f"{name}_low_um": low, f"{name}_high_um": high,
                          f"{name}_in_range": low <= entry[f"{name}_um"] <= high})
        forces.append(entry)
    return {"forces": {f"{f['force_pN']:g}": f for f in forces},
            "axial_outside": sum(not f["axial_in_range"] for f in forces),
            "transverse_outside": sum(not f["transverse_in_range"] for f in forces),
            "speed": max(f["speed"] for f in forces), "drift": max(f["drift"] for f in forces),
            "area_error": float(np.abs(series["area_error"]).max()),
            "volume_error": float(np.abs(series["volume_error"]).max()),
            "wall": float(wall[-1])}


# --------------------------------------------------------------------------
# Plane Poiseuille flow: a periodic channel driven by a body force

def poiseuille_series(y, time, gravity, viscosity, height, terms=200):
    """The start-up of plane Poiseuille flow from rest between no-slip walls at y = 0 and
    ``height``, driven by the body force ``gravity`` along the channel: u(y, t) [m/s]."""
    y = np.asarray(y, dtype=float)
    steady = gravity * y * (height - y) / (2.0 * viscosity)
    n = np.arange(1, 2 * terms, 2)[:, None]
    decay = np.exp(-(n * np.pi) ** 2 * viscosity * time / height ** 2)
    modes = 4.0 * gravity * height ** 2 / (viscosity * np.pi ** 3 * n ** 3) * \
        np.sin(n * np.pi * y[None, :] / height) * decay
    return steady - modes.sum(axis=0)


def poiseuille_profile(path, case):
    """A periodic channel's velocity against :func:`poiseuille_series`, relative to the
    steady centre-line velocity u_max = g H^2 / (8 nu): ``profile_rms`` (the RMS over the
    fluid at the last frame), ``transient_rms`` (the largest RMS over the frames) and
    ``flow_rate`` (the fluid's volume flux over the period against g H^3 / (12 nu), minus
    one, at the last frame). The walls are the first tank's floor and roof; the body force
    is gravity's component along the first periodic axis."""
    from parmps.result import open_result
    axis = "xyz".index(case["domain"]["periodic"][0])
    g, nu = case["physics"]["gravity"][axis], case["fluid"]["viscosity"]
    tank = case["tank"][0]
    across = len(tank["lower"]) - 1
    floor, height = tank["lower"][across], tank["upper"][across] - tank["lower"][across]
    period = case["domain"]["upper"][axis] - case["domain"]["lower"][axis]
    volume = case["particles"]["spacing"] ** len(tank["lower"])
    u_max = g * height ** 2 / (8.0 * nu)
    errors = []
    with open_result(path) as result:
        for frame in result.frames[1:]:
            fluid = frame.kind == 0
            y = frame.position[fluid, across] - floor
            u = frame.velocity[fluid, axis]
            errors.append(float(np.sqrt(np.mean((u - poiseuille_series(
                y, frame.time, g, nu, height)) ** 2)) / u_max))
        flux = float(u.sum() * volume / period)
        if across == 2:  # 3D: per metre of depth across the flow
            flux /= case["domain"]["upper"][1] - case["domain"]["lower"][1]
    steady_flux = g * height ** 3 / (12.0 * nu)
    return {"profile_rms": errors[-1], "transient_rms": max(errors),
            "flow_rate": flux / steady_flux - 1.0, "u_max": u_max,
            "end": float(frame.time)}


def hagen_poiseuille_series(r, time, gravity, viscosity, radius, terms=100):
    """The start-up of Hagen-Poiseuille flow from rest in a pipe of ``radius``, driven by the
    body force ``gravity`` along its axis: u(r, t) [m/s] at distances ``r`` from the axis."""
    from scipy.special import j0, j1, jn_zeros
    r = np.asarray(r, dtype=float)
    steady = gravity * (radius ** 2 - r ** 2) / (4.0 * viscosity)
    zeros = jn_zeros(0, terms)[:, None]
    modes = 2.0 * gravity * radius ** 2 / viscosity * j0(zeros * r[None, :] / radius) / \
        (zeros ** 3 * j1(zeros)) * np.exp(-zeros ** 2 * viscosity * time / radius ** 2)
    return steady - modes.sum(axis=0)


def hagen_poiseuille_profile(path, case, wall="pipe", radius=None):
    """A periodic pipe's velocity against :func:`hagen_poiseuille_series`, relative to the
    steady centre-line velocity u_max = g R^2 / (4 nu): ``profile_rms`` (last frame),
    ``transient_rms`` (the largest over the frames) and ``flow_rate`` (the fluid's volume flux
    over the period against pi g R^4 / (8 nu), minus one). The axis is the first periodic
    one; the pipe's radius and centre line are the wall ``wall``'s mesh's (its vertices' mean
    distance from their centroid's line), or ``radius`` [m]."""
    from parmps.geometry.mesh import read_mesh
    from parmps.result import open_result
    axis = "xyz".index(case["domain"]["periodic"][0])
    across = [a for a in range(3) if a != axis]
    g, nu = case["physics"]["gravity"][axis], case["fluid"]["viscosity"]
    spec = next(w for w in case["wall"] if w["name"] == wall)
    vertices, _ = read_mesh(spec["mesh"], wall)
    centre = vertices[:, across].mean(axis=0)
    if radius is None:
        radius = float(np.linalg.norm(vertices[:, across] - centre, axis=1).max())
    period = case["domain"]["upper"][axis] - case["domain"]["lower"][axis]
    volume = case["particles"]["spacing"] ** 3
    u_max = g * radius ** 2 / (4.0 * nu)
    errors = []
    with open_result(path) as result:
        for frame in result.frames[1:]:
            fluid = frame.kind == 0
            r = np.linalg.norm(frame.position[fluid][:, across] - centre, axis=1)
            u = frame.velocity[fluid, axis]
            errors.append(float(np.sqrt(np.mean((u - hagen_poiseuille_series(
                r, frame.time, g, nu, radius)) ** 2)) / u_max))
        flux = float(u.sum() * volume / period)
    steady_flux = np.pi * g * radius ** 4 / (8.0 * nu)
    return {"profile_rms": errors[-1], "transient_rms": max(errors),
            "flow_rate": flux / steady_flux - 1.0, "u_max": u_max, "radius": radius,
            "end": float(frame.time)}


# --------------------------------------------------------------------------
# Turek & Hron (2006): a displacement probe's oscillation against the benchmark's figures

def oscillation(time, value):
    """(mean, amplitude, frequency) of a periodic series as Turek & Hron report theirs: the
    mean (max + min)/2 and the amplitude (max - min)/2 over the series, the frequency from
    its crossings of that mean (NaN with fewer than three)."""
    time, value = np.asarray(time, dtype=float), np.asarray(value, dtype=float)
    high, low = float(value.max()), float(value.min())
    mean = 0.5 * (high + low)
    crossing = np.flatnonzero((value[:-1] - mean) * (value[1:] - mean) < 0.0)
    if len(crossing) < 3:
        return mean, 0.5 * (high - low), float("nan")
    at = time[crossing] + (mean - value[crossing]) / (value[crossing + 1] - value[crossing]) \
        * (time[crossing + 1] - time[crossing])
    return mean, 0.5 * (high - low), float((len(at) - 1) / (2.0 * (at[-1] - at[0])))


def flag_oscillation(path, case, probe="A", start=0.0, reference=None):
    """Point A's displacement (a displacement probe) over t >= ``start`` as the benchmark
    reports it, in mm and Hz: ``ux_mean``, ``ux_amplitude``, ``uy_mean``, ``uy_amplitude``,
    ``ux_frequency``, ``uy_frequency``; with ``reference`` (a table of the same names, the
    benchmark's figures) each one's relative error as ``<name>_error``."""
    from parmps.result import open_result
    with open_result(path) as result:
        series = result.probes[probe]
        time = np.asarray(series["time"])
        value = np.asarray(series["value"]) * 1000.0
    keep = time >= start
    measured = {"end": float(time[-1])}
    for k, axis in enumerate("xy"):
        mean, amplitude, frequency = oscillation(time[keep], value[keep, k])
        measured.update({f"u{axis}_mean": mean, f"u{axis}_amplitude": amplitude,
                         f"u{axis}_frequency": frequency})
    for name, expected in (reference or {}).items():
        measured[f"{name}_error"] = measured[name] / expected - 1.0
    return measured


def cylinder_coefficients(path, case, probe="cylinder", front="front", back="back",
                          start=0.0, end=None, mean_velocity=None, diameter=None,
                          reference=None):
    """Schäfer & Turek's steady figures from a force probe on the cylinder and pressure
    probes at its front and back points, time-averaged over [``start``, ``end``] (the run's
    end when None): ``drag`` and ``lift`` [N/m], ``cd = 2 F_D / (rho U^2 D)``, ``cl`` alike,
    ``delta_p = (p_front - p_back) / rho`` [m^2/s^2, the benchmark's Pa per unit density],
    each with its spread ``<name>_spread``: half the range of its means over the window's
    quarters (how far the window's mean is settled); with ``reference`` (a table of the same
    names) each one's relative error as ``<name>_error``. ``mean_velocity`` U and ``diameter``
    D [m] as the case's inlet and cylinder give them when None."""
    density = case["fluid"]["density"]
    if mean_velocity is None:
        mean_velocity = float(np.linalg.norm(case["inlet"][0]["velocity"]))
    if diameter is None:
        diameter = 2.0 * next(w["radius"] for w in case["wall"] if w["name"] == probe)
    t, force = read_probe(path, probe)
    end = float(t[-1]) if end is None else end
    scale = 0.5 * density * mean_velocity ** 2 * diameter
    series = {"drag": (t, force[:, 0]), "lift": (t, force[:, 1])}
    t_front, p_front = read_probe(path, front)
    t_back, p_back = read_probe(path, back)
    series["delta_p"] = (t_front, (p_front - np.interp(t_front, t_back, p_back)) / density)
    measured = {"end": end, "window": [start, end]}
    for name, (time, value) in series.items():
        edges = np.linspace(start, end, 5)
        quarters = [window_mean(time, value, a, b) for a, b in zip(edges[:-1], edges[1:])]
        measured[name] = window_mean(time, value, start, end)
        measured[f"{name}_spread"] = 0.5 * float(np.ptp(quarters))
    for name in ("drag", "lift"):
        coefficient = "cd" if name == "drag" else "cl"
        measured[coefficient] = measured[name] / scale
        measured[f"{coefficient}_spread"] = measured[f"{name}_spread"] / scale
    for name, expected in (reference or {}).items():
        measured[f"{name}_error"] = measured[name] / expected - 1.0
    return measured


# --------------------------------------------------------------------------
# A wall of any shape in a violent flow: the wall_crossing check's record

def wall_crossings(path, case, check):
    """A ``wall_crossing`` check's record (validation/dam_break_cylinder/): ``crossings``, the
    fluid particles that went through the wall's surface (deeper than half a spacing) over
    the run; ``deepest``, the deepest any fluid particle sat in its material [spacings];
    ``removed``, the fluid removed outside the domain over the fluid at t = 0; ``end`` [s]."""
    from parmps.result import open_result
    with open_result(path) as result:
        record = result.checks[check]
        total = np.asarray(record["total"])
        deepest = np.asarray(record["deepest"])
        d = result.diagnostics
        return {"crossings": int(total[-1]) if len(total) else 0,
                "deepest": float(np.nanmax(deepest) / case["particles"]["spacing"])
                if len(deepest) and np.any(np.isfinite(deepest)) else float("-inf"),
                "removed": float(d["n_escaped"][-1] / (d["n_fluid"][0] + d["n_escaped"][0])),
                "end": float(d["time"][-1])}


def womersley_velocity(r, time, amplitude, frequency, viscosity, radius):
    """Womersley's oscillating pipe flow driven by the body force A cos(omega t) along the
    axis, after its start-up has died out: u(r, t) = Re{A/(i omega) (1 - J0(i^(3/2) alpha
    r/R) / J0(i^(3/2) alpha)) e^(i omega t)}, alpha = R sqrt(omega / nu)."""
    from scipy.special import jv
    omega = 2.0 * np.pi * frequency
    alpha = radius * np.sqrt(omega / viscosity)
    k = 1j ** 1.5 * alpha
    shape = 1.0 - jv(0, k * np.asarray(r, dtype=float) / radius) / jv(0, k)
    return np.real(amplitude / (1j * omega) * shape * np.exp(1j * omega * np.asarray(time)))


def _harmonic(time, value, omega):
    """(amplitude, phase [rad]) of ``value``'s component at ``omega`` over whole periods of
    ``time`` (u ~ a cos(omega t - phase))."""
    c, s = np.cos(omega * time), np.sin(omega * time)
    a = 2.0 * np.trapz(value * c, time) / (time[-1] - time[0])
    b = 2.0 * np.trapz(value * s, time) / (time[-1] - time[0])
    return float(np.hypot(a, b)), float(np.arctan2(b, a))


def womersley_profile(path, case, wall="pipe", periods=2, radius=None):
    """A periodic pipe driven by an oscillating body force against :func:`womersley_velocity`
    over its last ``periods`` periods: the centre-line velocity (the mean over the fluid within
    1.5 l0 of the axis) against the solution at the same particles, its ``amplitude_error``
    (relative) and ``phase_error`` [degrees] at the forcing frequency, and ``profile_rms``, the
    RMS over the fluid and the frames of u - u_W relative to the centre-line amplitude."""
    from parmps.geometry.mesh import read_mesh
    from parmps.result import open_result
    axis = "xyz".index(case["domain"]["periodic"][0])
    across = [a for a in range(3) if a != axis]
    physics = case["physics"]
    amplitude, frequency = physics["gravity_amplitude"][axis], physics["gravity_frequency"]
    nu, spacing = case["fluid"]["viscosity"], case["particles"]["spacing"]
    spec = next(w for w in case["wall"] if w["name"] == wall)
    vertices, _ = read_mesh(spec["mesh"], wall)
    centre = vertices[:, across].mean(axis=0)
    if radius is None:
        radius = float(np.linalg.norm(vertices[:, across] - centre, axis=1).max())
    with open_result(path) as result:
        end = float(result.frames[-1].time)
        start = end - periods / frequency
        times, measured, expected, squares = [], [], [], []
        for frame in result.frames:
            if frame.time < start - 1e-12:
                continue
            fluid = frame.kind == 0
            r = np.linalg.norm(frame.position[fluid][:, across] - centre, axis=1)
            u = frame.velocity[fluid, axis]
            exact = womersley_velocity(r, frame.time, amplitude, frequency, nu, radius)
            near = r < 1.5 * spacing
            times.append(frame.time)
            measured.append(u[near].mean())
            expected.append(exact[near].mean())
            squares.append(np.mean((u - exact) ** 2))
    times = np.asarray(times)
    omega = 2.0 * np.pi * frequency
    got, got_phase = _harmonic(times, np.asarray(measured), omega)
    want, want_phase = _harmonic(times, np.asarray(expected), omega)
    phase = np.degrees(np.angle(np.exp(1j * (got_phase - want_phase))))
    return {"amplitude_error": got / want - 1.0, "phase_error": float(phase),
            "centre_amplitude": got, "womersley_number": radius * np.sqrt(omega / nu),
            "profile_rms": float(np.sqrt(np.mean(squares)) / want), "end": end}


# --------------------------------------------------------------------------
# A channel fed through a profiled inlet: what it delivers, and the profile downstream

def inlet_channel(path, case, section, start):
    """A 2D channel fed through its first ``[[inlet]]`` (validation/channel_inlet_2d/):
    ``flow_rate``, the volume that became fluid at the inlet by the end (the ``inflow``
    count times l0^2) over the requested mean velocity's integral times the opening's width,
    minus one; ``profile_rms``, over the frames from ``start`` [s] and the fluid with x in
    ``section`` [m], the RMS of u - 1.5 U (1 - (2 y'/h)^2) over 1.5 U (y' from the centre
    line, U the mean at the frame's time); ``end`` [s]."""
    from parmps.boundaries.open import mean_velocity
    from parmps.result import open_result
    inlet = case["inlet"][0]
    axis = int(np.flatnonzero(np.asarray(inlet["velocity"]) != 0.0)[0])
    cross = 1 - axis
    speed = abs(float(inlet["velocity"][axis]))
    mean = mean_velocity("inlet[0]", inlet, speed)
    low, high = inlet["lower"][cross], inlet["upper"][cross]
    width, middle = high - low, 0.5 * (low + high)
    spacing = case["particles"]["spacing"]
    squares = []
    with open_result(path) as result:
        d = result.diagnostics
        end = float(d["time"][-1])
        delivered = float(d["inflow"][-1]) * spacing ** 2
        for frame in result.frames:
            if frame.time < start:
                continue
            fluid = frame.kind == 0
            x = frame.position[fluid, axis]
            inside = (x >= section[0]) & (x <= section[1])
            y = frame.position[fluid, cross][inside] - middle
            u = abs(frame.velocity[fluid, axis][inside])
            peak = 1.5 * mean.value(frame.time)
            squares.append(np.mean((u - peak * (1.0 - (2.0 * y / width) ** 2)) ** 2)
                           / peak ** 2)
    return {"flow_rate": delivered / (mean.integral(end) * width) - 1.0,
            "profile_rms": float(np.sqrt(np.mean(squares))), "end": end}


# --------------------------------------------------------------------------
# One scene built two ways: the same scene from meshes against its boxes

def _kind_counts(path):
    """Fluid, wall and dummy particles, and all of them, of a result's first frame."""
    from parmps.core.particles import DUMMY, WALL
    with open_result(path) as result:
        kind = np.asarray(result.frames[0].kind)
    return {"fluid": int(np.sum(kind == FLUID)), "wall": int(np.sum(kind == WALL)),
            "dummy": int(np.sum(kind == DUMMY)), "total": int(len(kind))}


def built_alike(path, case, beside, probes, window, arrival_threshold):
    """A run against the same scene built another way (``beside``: {name: its result}, one
    entry): ``counts`` (each kind's and the total's, with ``<kind>_error`` the relative
    difference) and, per pressure probe of ``probes``, the ``mean`` over ``window`` [s]
    and the ``arrival`` (the first reading above ``arrival_threshold`` [Pa]) of each run,
    with ``mean_error`` (relative) and ``arrival_error`` [s]."""
    if len(beside) != 1:
        raise ValueError(f"built_alike compares with one other run, got {len(beside)}")
    (other_name, other), = beside.items()
    mine, theirs = _kind_counts(path), _kind_counts(other)
    counts = {"compared_with": other_name, **{f"{k}": v for k, v in mine.items()},
              **{f"{k}_beside": v for k, v in theirs.items()},
              **{f"{k}_error": mine[k] / theirs[k] - 1.0 if theirs[k] else 0.0
                 for k in mine}}
    out = {"counts": counts}
    for name in probes:
        rows = []
        for result in (path, other):
            t, p = read_probe(result, name)
            rows.append((window_mean(t, p, *window), first_crossing(t, p, arrival_threshold)))
        (mean, arrival), (mean_beside, arrival_beside) = rows
        out[name] = {"mean": mean, "mean_beside": mean_beside, "arrival": arrival,
                     "arrival_beside": arrival_beside,
                     "mean_error": mean / mean_beside - 1.0,
                     "arrival_error": arrival - arrival_beside}
    return out


# A capsule in simple shear: its Taylor deformation

def simple_shear(case):
    """(flow axis, gradient axis, shear rate [1/s]) of a case sheared between two wall boxes
    moving along one axis: the rate is their speed difference over the gap between their
    inner faces."""
    walls = [w for w in case["wall_box"] if any(w["velocity"])]
    if len(walls) != 2:
        raise ValueError("a simple shear needs exactly two moving wall boxes")
    speed = [np.asarray(w["velocity"], dtype=float) for w in walls]
    flow = int(np.argmax(np.abs(speed[0] - speed[1])))
    centre = [0.5 * (np.asarray(w["lower"]) + np.asarray(w["upper"])) for w in walls]
    gradient = int(np.argmax(np.abs(centre[0] - centre[1])))
    low, high = sorted(range(2), key=lambda k: centre[k][gradient])
    gap = walls[high]["lower"][gradient] - walls[low]["upper"][gradient]
    return flow, gradient, float((speed[high][flow] - speed[low][flow]) / gap)


def taylor_deformation(moment, plane):
    """(D, inclination) of shapes from their second moments ``moment`` (k, d, d): D = (L - B)
    / (L + B) of the semi-axes in the ``plane`` (flow axis, gradient axis) of the ellipsoid with
    the same moments (its semi-axes go as the square roots of the moment's eigenvalues), and
    the angle [rad] of its long axis from the flow axis towards the gradient axis."""
    moment = np.asarray(moment, dtype=float)
    block = moment[:, plane][:, :, plane]
    values, vectors = np.linalg.eigh(block)
    root = np.sqrt(np.clip(values, 0.0, None))
    deformation = (root[:, 1] - root[:, 0]) / (root[:, 1] + root[:, 0])
    long_axis = vectors[:, :, 1] * np.sign(vectors[:, 0, 1])[:, None]
    return deformation, np.arctan2(long_axis[:, 1], long_axis[:, 0])


def capsule_shear(path, case, body="capsule", steady_from=6.0, reference=None):
    """The Taylor deformation of a capsule in simple shear (Ramanujan & Pozrikidis 1998):
    ``capillary`` Ca = mu a gamma_dot / G_s from the case (mu = rho nu, a the shell's
    radius, G_s its membrane's shear modulus), the series ``strain`` (gamma_dot t),
    ``deformation`` and ``inclination`` (in units of pi), the ``steady`` D (mean over
    gamma_dot t >= ``steady_from``), its ``drift`` (the change of D over that window),
    ``slope`` D/Ca, the largest ``volume_error``; with ``reference`` (a table of
    published steady D, columns Ca and the sources) the published values at this Ca and
    ``steady_error`` against each as ``<source>_error``."""
    flow, gradient, rate = simple_shear(case)
    spec = next(b for b in case["body"] if b["name"] == body)
    viscosity = case["fluid"]["density"] * case["fluid"]["viscosity"]
    capillary = viscosity * spec["radius"] * rate / spec["shear_modulus"]
    with open_result(path) as result:
        series = result.bodies[body]
        time = np.asarray(series["time"])
        moment = np.asarray(series["second_moment"])
        volume_error = float(np.abs(series["volume_error"]).max())
    deformation, inclination = taylor_deformation(moment, [flow, gradient])
    strain = rate * time
    window = strain >= steady_from
    if not window.any():
        raise ValueError(f"the run ends at gamma_dot t = {strain[-1]:.3g}, before the steady "
                         f"window from {steady_from}")
    steady = float(deformation[window].mean())
    measured = {"capillary": capillary, "shear_rate": rate, "end_strain": float(strain[-1]),
                "steady": steady, "slope": steady / capillary,
                "drift": float(deformation[window][-1] - deformation[window][0]),
                "inclination_steady": float(inclination[window].mean() / math.pi),
                "volume_error": volume_error, "strain": strain, "deformation": deformation,
                "inclination": inclination / math.pi}
    if reference is not None:
        table = reference_table(reference)
        row = int(np.argmin(np.abs(np.asarray(table["Ca"]) - capillary)))
        if abs(table["Ca"][row] / capillary - 1.0) < 1e-6:
            for source, values in table.items():
                if source != "Ca" and np.isfinite(values[row]):
                    measured[source] = float(values[row])
                    measured[f"{source}_error"] = steady / float(values[row]) - 1.0
    return measured
