#!/usr/bin/env python3
"""The validation report: error against run time, pressure schemes, stability map.

    scripts/study.py [--quick] [--ranks 1 2] [--docs docs] [--work out/study]
                     [--only dam_break hydrostatic schemes solid stiffness stability box]

Runs the sweeps of issue 6 through the command line a user would type
(``python -m parmps CASE --set ...``, under ``mpirun -n R`` for R > 1), every run
under a timeout, then writes ``DOCS/validation.md`` with its PNG figures and
tables, and ``DOCS/validation.json`` with every number in them. ``--quick``
runs a few coarse points of each sweep (for the test suite, under a minute);
its report goes to ``out/study-quick/`` unless --docs says otherwise.

The cases, metrics and tolerances are those of ``validation/<name>/``; every
physical size comes from the case files, and resolutions are fractions of them
(l0 = a/m for the dam break's column a, H/m for the still tank's depth H).

Wall times are the run's own loop time (``/diagnostics/wall_seconds`` at the
last step: no interpreter start-up, no numba loading), on a shared 2-core
machine: they are noisy, and the report says so next to every figure.
"""

import argparse
import json
import math
import os
import platform
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from parmps import validation
from parmps.tools import analysis
from parmps.validation import launch
from parmps.validation.presets import SCHEMES, STUDIED
from parmps.tools.analysis import log_slope as slope

# The pressure schemes of the sweeps: presets of the package's one table.
PRESSURE_SCHEMES = {label: SCHEMES[label] for label in STUDIED}


# --------------------------------------------------------------------------
# Running parmps

def run(case, out, sets=(), end_time=None, petsc=(), ranks=1, timeout=600):
    """One run through the package's launcher, from the repository (commands shown
    relative to it); returns its record (parmps.validation.launch.run)."""
    return launch.run(case, out, sets, end_time, petsc, ranks, timeout, root=ROOT, cwd=ROOT)


def median_wall(records):
    walls = [r["wall"] for r in records if "wall" in r]
    return float(np.median(walls)) if walls else math.nan


def margin_sets(case, spacing, margin):
    """Domain overrides: the case's tank plus ``margin`` on every side but the top (the case's)."""
    tank = case["tank"][0]
    return [f"domain.lower=[{tank['lower'][0] - margin:.10g}, {tank['lower'][1] - margin:.10g}]",
            f"domain.upper=[{tank['upper'][0] + margin:.10g}, "
            f"{case['domain']['upper'][1]:.10g}]"]


def wall_margin(case, spacing):
    """The case's own margin around its tank, or 5 l0 where coarse walls reach further."""
    return max(case["tank"][0]["lower"][0] - case["domain"]["lower"][0], 5 * spacing)


def hydrostatic_record(result, settle_time):
    """The still tank's metric, under the report's names."""
    measured = analysis.hydrostatic_pressure_error(result, analysis.result_case(result),
                                                   settle_time)
    return {"mean_error": measured["rms"], "bottom_mean": measured["bottom"],
            **{key: measured[key] for key in ("bottom_std", "noise", "speed_rms",
                                              "bottom_series", "bottom_times")}}


# --------------------------------------------------------------------------
# Sweeps

class Study:
    def __init__(self, args):
        self.args = args
        self.quick = args.quick
        self.work = args.work
        self.results = {}
        self.figures = {}
        self.table_rows = []
        self.cache = {}
        self.dam = validation.load("dam_break")
        self.hydro = validation.load("hydrostatic")
        self.solid_check = validation.load("mass_spring_7x7")
        self.box_check = validation.load("box_in_flow")

    def out(self, *parts):
        return os.path.join(self.work, *parts)

    def log(self, text):
        print(text, flush=True)

    def repeat(self, *args, repeats=1, **kwargs):
        """Run a case ``repeats`` times; the record of the first, with the median wall time."""
        key = json.dumps([args, sorted(kwargs.items()), repeats], default=str)
        if key in self.cache:
            return dict(self.cache[key])
        records = [run(*args, **kwargs) for _ in range(repeats)]
        record = dict(records[0])
        record["wall"] = median_wall(records)
        record["repeats"] = len(records)
        self.cache[key] = dict(record)
        return record

    # -- dam break -----------------------------------------------------------
    def dam_break_point(self, m, ranks, scheme_sets=(), label="default", repeats=1):
        case = self.dam.case()
        lower, upper = analysis.fluid_extent(case)
        spacing = (upper[0] - lower[0]) / m
        out = self.out("dam_break", f"{label}_m{m}_r{ranks}")
        sets = [f"particles.spacing={spacing:.10g}",
                f"time.output_interval={self.dam.run['output_interval']:.10g}"]
        sets += margin_sets(case, spacing, wall_margin(case, spacing)) + list(scheme_sets)
        end = self.dam.run["until"] / analysis.dam_break_time_scale(case)
        record = self.repeat(self.dam.case_path, out, sets, end,
                             ranks=ranks, repeats=repeats, timeout=900)
        record.update(m=m, spacing=spacing, label=label)
        if record["status"] == 0:
            measured = self.dam.measure(record["result"])
            record.update(rms=measured["rms"], rms_shifted=measured["rms_delayed"],
                          delay=measured["delay"],
                          curve=(measured["T"].tolist(), measured["Z"].tolist()))
        self.log(f"dam break {label} a/{m} on {ranks}: {record['outcome']}, "
                 f"rms {record.get('rms', math.nan):.4f}, wall {record.get('wall', math.nan):.2f} s")
        return record

    def dam_break(self):
        levels = (6, 8) if self.quick else (10, 14, 20, 28, 40)
        ranks_list = self.args.ranks
        records = []
        for ranks in ranks_list:
            for m in levels:
                if self.quick and ranks > 1 and m != levels[-1]:
                    continue
                records.append(self.dam_break_point(m, ranks, repeats=1))
        self.results["dam_break"] = records
        self.results["dam_break_levels"] = list(levels)

    # -- hydrostatic ---------------------------------------------------------
    def hydrostatic_point(self, m, ranks, scheme_sets=(), label="default", end=1.0, repeats=1):
        case = self.hydro.case()
        lower, upper = analysis.fluid_extent(case)
        spacing = (upper[1] - lower[1]) / m
        out = self.out("hydrostatic", f"{label}_m{m}_r{ranks}_t{end:g}")
        sets = [f"particles.spacing={spacing:.10g}", "time.output_interval=0.01"]
        sets += margin_sets(case, spacing, wall_margin(case, spacing)) + list(scheme_sets)
        record = self.repeat(self.hydro.case_path, out, sets, end,
                             ranks=ranks, repeats=repeats, timeout=900)
        record.update(m=m, spacing=spacing, label=label, t_end=end)
        if record["status"] == 0:
            record.update(hydrostatic_record(record["result"],
                                             min(self.hydro.study["settle_time"], end / 2)))
        self.log(f"hydrostatic {label} H/{m} on {ranks} to {end} s: {record['outcome']}, "
                 f"mean err {record.get('mean_error', math.nan):.4f}, "
                 f"bottom std {record.get('bottom_std', math.nan):.4f}, "
                 f"wall {record.get('wall', math.nan):.2f} s")
        return record

    def hydrostatic(self):
        levels = (6, 10) if self.quick else (10, 20, 30, 40)
        end = 0.3 if self.quick else 1.0
        records = []
        for ranks in self.args.ranks:
            for m in levels:
                if self.quick and ranks > 1:
                    continue
                records.append(self.hydrostatic_point(m, ranks, end=end))
        self.results["hydrostatic"] = records

    # -- pressure schemes ----------------------------------------------------
    def schemes(self):
        hydro_m, hydro_end = (10, 0.3) if self.quick else (20, 2.0)
        dam_levels = (8,) if self.quick else (20, 40)
        repeats = 1 if self.quick else 3
        records = []
        for label, sets in PRESSURE_SCHEMES.items():
            if self.quick and label == "default, no clamp":
                continue
            hydro = self.hydrostatic_point(hydro_m, 1, sets, label=label, end=hydro_end,
                                           repeats=repeats)
            hydro["case"] = "hydrostatic"
            records.append(hydro)
            for m in dam_levels:
                if label == "default, no clamp" and m != dam_levels[0]:
                    continue
                dam = self.dam_break_point(m, 1, sets, label=label)
                dam["case"] = "dam_break"
                records.append(dam)
        self.results["schemes"] = records

    # -- 7x7 mass-spring -----------------------------------------------------
    def solid(self):
        check = self.solid_check
        case_path = check.case_path
        end = 0.6 if self.quick else check.case()["time"]["end"]
        substeps = ([1e-3, 2.5e-4] if self.quick else
                    [1e-3, 5e-4, 2.5e-4, 1.25e-4, 6.25e-5, 3.125e-5])
        reference = 3.125e-5 / 4 if not self.quick else 6.25e-5
        records = []
        ref = run(case_path, self.out("solid", "reference"),
                  [f"solid.substep={reference:.10g}"], end)
        ref_tip = analysis.tip_trajectory(ref["result"], analysis.result_case(ref["result"]))
        for substep in substeps:
            for constraint in ((True,) if self.quick else (True, False)):
                name = f"h{substep:g}_{'constrained' if constraint else 'free'}"
                sets = [f"solid.substep={substep:.10g}",
                        f"body.0.volume_constraint={'true' if constraint else 'false'}"]
                if constraint:
                    record = self.repeat(case_path, self.out("solid", name), sets, end,
                                         repeats=1 if self.quick else 3)
                    reference_tip = ref_tip
                else:
                    record = run(case_path, self.out("solid", name), sets, end)
                    reference_tip = None
                record.update(substep=substep, constraint=constraint)
                if record["status"] == 0:
                    case = analysis.result_case(record["result"])
                    record["volume_error"] = analysis.volume_error(record["result"],
                                                                   case)["volume_error"]
                    tip = analysis.tip_trajectory(record["result"], case)
                    record["tip"] = tip[1].tolist()
                    record["tip_time"] = tip[0].tolist()
                    if reference_tip is not None:
                        diff = tip[1] - np.interp(tip[0], *reference_tip)
                        record["tip_error"] = float(np.sqrt(np.mean(diff ** 2)))
                records.append(record)
                self.log(f"7x7 h = {substep:g} constraint={constraint}: {record['outcome']}, "
                         f"|eps|max {record.get('volume_error', math.nan):.3e}, "
                         f"tip err {record.get('tip_error', math.nan):.3e}")
        self.results["solid"] = records
        self.results["solid_reference_substep"] = reference

    # -- stiffness -----------------------------------------------------------
    def stiffness(self):
        case_path = self.solid_check.case_path
        # The quick study's two stiff points lie well above one substep (9 and 273 at
        # 1e5 and 1e8), where the slope is fitted (more than 4 substeps).
        exponents = (1, 5, 8) if self.quick else range(1, 10)
        end = 0.02 if self.quick else 0.05
        records = []
        for e in exponents:
            k = 10.0 ** e
            sets = [f"body.0.stiffness={k:.10g}", f"body.0.shear_stiffness={k:.10g}"]
            record = run(case_path, self.out("stiffness", f"k1e{e}"), sets, end, timeout=600)
            record.update(k=k, substeps=substeps_per_step(self.solid_check.case(sets)))
            self.log(f"stiffness {k:g}: {record['outcome']}, {record['substeps']} substeps, "
                     f"wall {record.get('wall', math.nan):.2f} s")
            records.append(record)
            self.table_rows.append(("7x7 mass-spring, automatic substeps", f"k = {k:.0e} N/m",
                                    record))
        self.results["stiffness"] = records

    # -- stability map -------------------------------------------------------
    def stability(self):
        dam_case, hydro_case = self.dam.case(), self.hydro.case()
        dam_lower, dam_upper = analysis.fluid_extent(dam_case)
        column = dam_upper[0] - dam_lower[0]
        dam_end = self.dam.run["until"] / analysis.dam_break_time_scale(dam_case)
        m = 10 if self.quick else 20
        # Twice the case's margin around the tank: spray at coarse l0 reaches further.
        coarse = [f"particles.spacing={column / m:.10g}", "time.output_interval=0.02"]
        coarse += margin_sets(dam_case, column / m, 2 * wall_margin(dam_case, 0.0))
        rows = []
        for dt in ((0.004,) if self.quick else (0.0005, 0.002, 0.004, 0.01)):
            rows.append(("dam break a/%d, fixed dt" % m, f"time.fixed_dt = {dt:g} s",
                         run(self.dam.case_path, self.out("stability", f"fixed_dt{dt:g}"),
                             coarse + [f"time.fixed_dt={dt:.10g}"], dam_end, timeout=300)))
        for nu in (() if self.quick else (0.0, 1e-9)):
            rows.append(("dam break a/%d, inviscid" % m, f"fluid.viscosity = {nu:g} m²/s",
                         run(self.dam.case_path, self.out("stability", f"nu{nu:g}"),
                             coarse + [f"fluid.viscosity={nu:.10g}"], dam_end, timeout=300)))
        if not self.quick:
            rows += self.tall_rows(hydro_case)
            # A dam break whose scene is ten times larger, at the same l0 relative to it.
            raw = self.dam.raw_case()
            high = [f"particles.spacing={10 * column / 20:.10g}", "time.output_interval=0.05"]
            high += validation.scaled_overrides(raw, 10.0)
            end = self.dam.run["until"] / analysis.dam_break_time_scale(self.dam.case(high))
            rows.append((f"dam break, scene 10x larger (a = {10 * column:g} m, l0 = a/20)",
                         f"a = {10 * column:g} m",
                         run(self.dam.case_path, self.out("stability", "dam_high"), high, end,
                             timeout=600)))
        for row in rows:
            self.log(f"{row[0]} {row[1]}: {row[2]['outcome']}")
        self.table_rows.extend(rows)

    def tall_rows(self, case):
        """The still tank with a column ten times higher, and the case's own, at l0 = H/10."""
        lower, upper = analysis.fluid_extent(case)
        depth = upper[1] - lower[1]
        spacing = depth / 10
        margin = 5 * spacing
        settle = self.hydro.study["settle_time"]
        tall = [f"particles.spacing={spacing:.10g}",
                f"fluid_block.0.upper=[{upper[0]:.10g}, {lower[1] + 10 * depth:.10g}]",
                f"tank.0.upper=[{case['tank'][0]['upper'][0]:.10g}, "
                f"{lower[1] + 11 * depth:.10g}]",
                f"domain.lower=[{lower[0] - margin:.10g}, {lower[1] - margin:.10g}]",
                f"domain.upper=[{upper[0] + margin:.10g}, {lower[1] + 12 * depth:.10g}]",
                "time.output_interval=0.02"]
        same = [f"particles.spacing={spacing:.10g}", "time.output_interval=0.02"]
        same += margin_sets(case, spacing, margin)
        rows = []
        for sets, name, label in ((tall, "tall", "column 10x higher"),
                                  (same, "short", "the case's column")):
            record = run(self.hydro.case_path, self.out("stability", name), sets, 1.0,
                         timeout=600)
            height = depth * (10 if name == "tall" else 1)
            if record["status"] == 0:
                record.update(hydrostatic_record(record["result"], settle))
                record["note"] = (f"mean bottom-pressure error {100 * record['bottom_mean']:+.1f} %, "
                                  f"std {100 * record['bottom_std']:.1f} % of rho g H")
            rows.append((f"hydrostatic, {label} (H = {height:g} m, l0 = {100 * spacing:g} cm)",
                         f"H = {height:g} m", record))
        return rows

    # -- box in flow (issue 5) -----------------------------------------------
    def box(self):
        self.results["box"] = box_study(self, self.box_check)


def box_study(study, check):
    """Box in flow: centroid at the end time against resolution; inflow and density rows.

    The channel's dimensions are whole multiples of 1 cm, so the resolutions
    are the case's l0, its half and its third; the box keeps its physical size (more
    nodes at the same spacing as the fluid, as a body in a fluid must).
    """
    base, case = check.raw_case(), check.case()
    spacing = case["particles"]["spacing"]
    body = case["body"][0]
    name = body["name"] or "body0"
    end = 0.02 if study.quick else 0.3
    ranks = study.args.ranks[-1]
    records = []
    for factor in ((1,) if study.quick else (1, 0.5, 1 / 3)):
        sets = rescale_sets(base, factor)
        if sets is None:
            continue
        record = run(check.case_path, study.out("box", f"f{factor:g}"), sets, end, ranks=ranks,
                     timeout=1800)
        record.update(spacing=spacing * factor, factor=factor)
        if record["status"] == 0:
            record["centroid"] = analysis.solid_series(record["result"],
                                                       name)["centroid"][-1].tolist()
        records.append(record)
        study.log(f"box in flow l0 x{factor:g}: {record['outcome']}, "
                  f"centroid {record.get('centroid')}, wall {record.get('wall', math.nan):.1f} s")
    short_end = 0.02 if study.quick else 0.2
    if case["inlet"]:
        velocity = case["inlet"][0]["velocity"]
        for scale in (() if study.quick else (2.0, 5.0, 10.0)):
            # The inlet and the initial water, so the start is not impulsive.
            sets = [f"inlet.0.velocity=[{scale * velocity[0]:.10g}, {scale * velocity[1]:.10g}]"]
            for k, block in enumerate(case["fluid_block"]):
                v = block["velocity"]
                sets.append(f"fluid_block.{k}.velocity=[{scale * v[0]:.10g}, {scale * v[1]:.10g}]")
            record = run(check.case_path, study.out("box", f"u{scale:g}"), sets, short_end,
                         ranks=ranks, timeout=900)
            study.log(f"box in flow {scale:g} U0: {record['outcome']}")
            study.table_rows.append(("box in flow, inflow velocity",
                                     f"{scale:g} × U0 = {scale * abs(velocity[0] or velocity[1]):g} m/s, "
                                     f"to t = {short_end:g} s", record))
    rho = case["fluid"]["density"]
    for ratio in (() if study.quick else (0.1, 0.5, 2.0, 10.0)):
        sets = ([f"body.0.density={ratio * rho:.10g}"] if not body["node_mass"] else
                [f"body.0.node_mass={body['node_mass'] * ratio:.10g}"])
        record = run(check.case_path, study.out("box", f"rho{ratio:g}"), sets, short_end,
                     ranks=ranks, timeout=900)
        study.log(f"box in flow density ratio {ratio:g}: {record['outcome']}")
        study.table_rows.append(("box in flow, solid/fluid density", f"ratio {ratio:g}, "
                                 f"to t = {short_end:g} s", record))
    return {"records": records, "end": end, "ranks": ranks}


def rescale_sets(base, factor):
    """Overrides that run the box-in-flow case at spacing x factor (box size kept), or None."""
    if factor == 1:
        return []
    spacing = base["particles"]["spacing"] * factor
    sets = [f"particles.spacing={spacing:.10g}"]
    for k, body in enumerate(base.get("body", [])):
        if body.get("type", "lattice") != "lattice":
            return None
        cells = [(body["nx"] - 1) / factor, (body["ny"] - 1) / factor]
        if any(abs(c - round(c)) > 1e-9 or c < 1 for c in cells):
            return None
        sets += [f"body.{k}.spacing={spacing:.10g}", f"body.{k}.nx={int(round(cells[0])) + 1}",
                 f"body.{k}.ny={int(round(cells[1])) + 1}"]
        if "node_mass" in body:
            sets.append(f"body.{k}.node_mass={body['node_mass'] * factor ** 2:.10g}")
    return sets


def substeps_per_step(case):
    """Automatic substeps per outer step of the case's first body (the solver's own rule)."""
    from parmps.solids.mass_spring.model import MassSpringModel
    system = MassSpringModel.from_case(case)
    body = case["body"][0]
    return system.substep_counts(case["time"]["fixed_dt"])[body["name"] or "body0"]


# --------------------------------------------------------------------------
# --------------------------------------------------------------------------
# The report

def machine():
    model = platform.processor() or "unknown CPU"
    try:
        with open("/proc/cpuinfo") as handle:
            for line in handle:
                if line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else math.nan
    return f"{model}, {os.cpu_count()} cores, Linux, load {load:.1f} at start (shared machine)"


def stamp(figure, text):
    figure.text(0.01, 0.005, text, fontsize=6, color="0.35", ha="left", va="bottom", wrap=True)


class Report:
    def __init__(self, study, docs, command):
        self.study = study
        self.docs = docs
        self.command = command
        self.machine = machine()
        self.lines = []
        self.files = []
        os.makedirs(docs, exist_ok=True)

    def figure(self, name, figure, ranks_text, command):
        path = os.path.join(self.docs, name)
        stamp(figure, f"{self.machine}; {ranks_text}; command: {command}")
        figure.savefig(path, dpi=80)
        import matplotlib.pyplot as plt
        plt.close(figure)
        self.files.append(path)
        return name


def write_report(study, docs, command):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    report = Report(study, docs, command)
    results = study.results
    md = []
    add = md.append
    add("# Validation report: error against run time, pressure schemes, stability\n")
    add(f"Generated by `{command}` (every number and figure below). Machine: {report.machine}. "
        "Wall times are each run's own loop time (`/diagnostics/wall_seconds`, no start-up); "
        "the machine is shared with other developers' runs, so they are noisy to tens of "
        "percent — the timing-sensitive comparisons use medians of repeats where noted.\n")
    numbers = {}

    # Dam break -------------------------------------------------------------
    records = [r for r in results.get("dam_break", []) if "rms" in r]
    if records:
        figure, axes = plt.subplots(1, 2, figsize=(9, 3.8))
        add("## Dam break: surge front against Martin & Moyce (1952), error against wall time\n")
        dam = study.dam
        until = dam.metric["compare_until"]
        add(f"RMS relative error of the front Z = x/a for T <= {until:g}, unshifted and with "
            "the best constant delay of the experiment's start, against the loop wall time; "
            f"run to T = {dam.run['until']:g} (`validation/dam_break/`). The original MPS "
            "(Koshizuka & Oka 1996) leads the same record by T ≈ 0.25 and Hirt & Nichols' VOF "
            "by ≈ 0.29: the record defines neither the release nor t = 0, so the front is "
            "reported here, not judged; the accuracy gate is the Lobovsky case.\n")
        add("| ranks | l0 | steps | wall [s] | RMS error | RMS error, delayed | delay T |")
        add("| --- | --- | --- | --- | --- | --- | --- |")
        for ranks in sorted({r["ranks"] for r in records}):
            mine = sorted((r for r in records if r["ranks"] == ranks), key=lambda r: r["m"])
            walls = [r["wall"] for r in mine]
            rms = [r["rms"] for r in mine]
            shifted = [r["rms_shifted"] for r in mine]
            p_wall, p_wall_s = slope(walls, rms), slope(walls, shifted)
            p_l0 = slope([r["spacing"] for r in mine], shifted)
            marker = "o-" if ranks == 1 else "s--"
            axes[0].loglog(walls, rms, marker, label=f"{ranks} rank(s), unshifted: "
                           f"slope {p_wall:.2f}")
            axes[0].loglog(walls, shifted, marker, mfc="none",
                           label=f"{ranks} rank(s), delayed: slope {p_wall_s:.2f} "
                                 f"(order {p_l0:.2f} in l0)")
            for r in mine:
                add(f"| {ranks} | a/{r['m']} | {r['steps']} | {r['wall']:.2f} | "
                    f"{100 * r['rms']:.1f} % | {100 * r['rms_shifted']:.1f} % | {r['delay']:.2f} |")
            numbers[f"dam_break_slope_wall_r{ranks}"] = p_wall_s
            numbers[f"dam_break_order_l0_r{ranks}"] = p_l0
            if ranks == 1:
                for r in mine:
                    t, z = r["curve"]
                    axes[1].plot(t, z, "-", lw=1, label=f"a/{r['m']}")
        reference = analysis.reference_table(dam.reference)
        t_exp, z_exp = reference["T"], reference["Z"]
        axes[1].plot(t_exp, z_exp, "ko", mfc="none", ms=4, label="Martin & Moyce")
        axes[0].set_xlabel("loop wall time [s]")
        axes[0].set_ylabel(f"RMS relative front error, T <= {until:g}")
        axes[0].legend(fontsize=7)
        axes[0].grid(alpha=0.3, which="both")
        axes[1].set_xlabel(r"$T = t\sqrt{2g/a}$")
        axes[1].set_ylabel("Z = x/a")
        axes[1].set_xlim(0, 3.5)
        axes[1].legend(fontsize=7)
        axes[1].grid(alpha=0.3)
        figure.suptitle("Dam break: front error against wall time (slope = observed order in "
                        "wall time)", fontsize=9)
        figure.tight_layout(rect=(0, 0.04, 1, 1))
        ranks_text = "ranks " + ", ".join(str(r) for r in sorted({r["ranks"] for r in records}))
        name = report.figure("validation_dam_break.png", figure, ranks_text,
                             records[0]["command"].replace(f"a/{records[0]['m']}", "a/m"))
        add(f"\n![dam break]({name})\n")
        add("Command of one point: `" + records[-1]["command"] + "`.\n")
        add(dam_break_comment(records))

    # Hydrostatic -------------------------------------------------------------
    records = [r for r in results.get("hydrostatic", []) if "mean_error" in r]
    if records:
        add("## Hydrostatic tank: time-averaged pressure error against wall time\n")
        add("Error of the time-averaged pressure against rho g (H - y), RMS over the fluid "
            f"(top row excluded), relative to rho g H, frames after t = {study.hydro.study['settle_time']} s "
            "(or half the run); and the "
            "pressure noise (standard deviation over time of the bottom row's pressure).\n")
        add("| ranks | l0 | fluid rows | end [s] | wall [s] | time-avg. error | bottom mean | "
            "bottom std | RMS speed at end [m/s] |")
        add("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        figure, axes = plt.subplots(figsize=(6.4, 4.2))
        for ranks in sorted({r["ranks"] for r in records}):
            mine = sorted((r for r in records if r["ranks"] == ranks), key=lambda r: r["m"])
            walls = [r["wall"] for r in mine]
            errors = [r["mean_error"] for r in mine]
            p_wall = slope(walls, errors)
            p_l0 = slope([r["spacing"] for r in mine], errors)
            axes.loglog(walls, errors, "o-" if ranks == 1 else "s--",
                        label=f"{ranks} rank(s): slope {p_wall:.2f} in wall time, "
                              f"order {p_l0:.2f} in l0")
            axes.loglog(walls, [r["bottom_std"] for r in mine], "o:" if ranks == 1 else "s:",
                        mfc="none", label=f"{ranks} rank(s): bottom-pressure std")
            numbers[f"hydrostatic_order_l0_r{ranks}"] = p_l0
            for r in mine:
                add(f"| {ranks} | {r['spacing'] * 100:.3g} cm | {r['m']} | {r['t_end']:g} | "
                    f"{r['wall']:.2f} | {100 * r['mean_error']:.2f} % | "
                    f"{100 * r['bottom_mean']:+.2f} % | {100 * r['bottom_std']:.2f} % | "
                    f"{r['speed_rms']:.3f} |")
        axes.set_xlabel("loop wall time [s]")
        axes.set_ylabel("error / rho g H")
        axes.grid(alpha=0.3, which="both")
        axes.legend(fontsize=7)
        axes.set_title("Hydrostatic tank: pressure error against wall time", fontsize=9)
        figure.tight_layout(rect=(0, 0.04, 1, 1))
        name = report.figure("validation_hydrostatic.png", figure, "ranks " + ", ".join(
            str(r) for r in sorted({r["ranks"] for r in records})), records[0]["command"])
        add(f"\n![hydrostatic]({name})\n")
        add("Command of one point: `" + records[-1]["command"] + "`.\n")

    # Schemes -------------------------------------------------------------------
    records = results.get("schemes", [])
    if records:
        add("## Pressure schemes compared\n")
        add("Every registered scheme on the still tank, the Lobovsky case, the coupled scenes "
            "and cost: [validation_schemes.md](validation_schemes.md) "
            "(`scripts/compare_schemes.py`). Here the original scheme (`density`: density "
            "source, minimum gradient) against the default (mixed source, gamma 0.1, corrected "
            "gradient; docs/design.md §1.4). Overrides of each: " + "; ".join(
                f"{label}: " + (", ".join(f"`{item}`" for item in sets) or "none")
                for label, sets in PRESSURE_SCHEMES.items()) +
            ". Hydrostatic: median wall time of repeats; dam break: one run each.\n")
        add("| scheme | case | l0 | outcome | wall [s] | time-avg. error | bottom mean | "
            "bottom std (noise) | RMS speed at end | front RMS | front RMS, delayed | "
            "mean KSP its |")
        add("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for r in records:
            def pct(key, sign=""):
                return f"{100 * r[key]:{sign}.2f} %" if key in r else "—"
            level = f"H/{r['m']}" if r["case"] == "hydrostatic" else f"a/{r['m']}"
            speed = f"{r['speed_rms']:.3f}" if "speed_rms" in r else "—"
            add(f"| {r['label']} | {r['case']} | {level} | {short(r['outcome'])} | "
                f"{r.get('wall', math.nan):.2f} | {pct('mean_error')} | "
                f"{pct('bottom_mean', '+')} | {pct('bottom_std')} | {speed} | {pct('rms')} | "
                f"{pct('rms_shifted')} | {r.get('ksp_mean', math.nan):.1f} |")
        hydro = [r for r in records if r["case"] == "hydrostatic" and "bottom_series" in r]
        if hydro:
            figure, axes = plt.subplots(figsize=(6.4, 3.8))
            for r in hydro:
                axes.plot(r["bottom_times"], 100 * np.asarray(r["bottom_series"]), lw=1,
                          label=f"{r['label']}: std {100 * r['bottom_std']:.2f} %, "
                                f"wall {r['wall']:.1f} s")
            axes.set_xlabel("t [s]")
            axes.set_ylabel("bottom pressure error [% of rho g H]")
            axes.grid(alpha=0.3)
            axes.legend(fontsize=7)
            axes.set_title(f"Hydrostatic tank, l0 = H/{hydro[0]['m']}: bottom pressure over time",
                           fontsize=9)
            figure.tight_layout(rect=(0, 0.04, 1, 1))
            name = report.figure("validation_schemes.png", figure, "1 rank",
                                 hydro[-1]["command"])
            add(f"\n![schemes]({name})\n")
        add(scheme_verdict(records))

    # Solid ---------------------------------------------------------------------
    records = [r for r in results.get("solid", []) if r.get("status") == 0]
    if records:
        add("## 7×7 mass-spring body: volume error and tip trajectory against substep and "
            "wall time\n")
        add("`cases/mass_spring_7x7.toml` (pressed for 0.5 s, then released) with a fixed "
            "substep `solid.substep`; the tip is the top middle node's y, compared (RMS over "
            f"the frames) with a run at substep {results['solid_reference_substep']:.3g} s. "
            "Solid-only runs do the same work on every rank, so they run on 1 rank.\n")
        add("| substep [s] | constraint | wall [s] | max volume error | tip RMS error [m] |")
        add("| --- | --- | --- | --- | --- |")
        for r in records:
            add(f"| {r['substep']:.4g} | {'yes' if r['constraint'] else 'no'} | "
                f"{r['wall']:.3f} | {r.get('volume_error', math.nan):.2e} | "
                f"{r.get('tip_error', math.nan):.2e} |" if r["constraint"] else
                f"| {r['substep']:.4g} | no | {r['wall']:.3f} | "
                f"{r.get('volume_error', math.nan):.2e} | — |")
        constrained = [r for r in records if r["constraint"] and "tip_error" in r]
        figure, axes = plt.subplots(1, 3, figsize=(11, 3.6))
        h = [r["substep"] for r in constrained]
        tip = [r["tip_error"] for r in constrained]
        vol = [r["volume_error"] for r in constrained]
        wall = [r["wall"] for r in constrained]
        axes[0].loglog(h, tip, "o-", label=f"tip error: order {slope(h, tip):.2f}")
        axes[0].loglog(h, vol, "s-", label=f"max |volume error|: order {slope(h, vol):.2f}")
        axes[0].set_xlabel("substep [s]")
        axes[1].loglog(wall, tip, "o-", label=f"tip error: slope {slope(wall, tip):.2f}")
        axes[1].loglog(wall, vol, "s-", label=f"volume error: slope {slope(wall, vol):.2f}")
        axes[1].set_xlabel("loop wall time [s]")
        for a in axes[:2]:
            a.grid(alpha=0.3, which="both")
            a.legend(fontsize=7)
        numbers["solid_tip_order"] = slope(h, tip)
        for r in constrained:
            axes[2].plot(r["tip_time"], r["tip"], lw=1, label=f"h = {r['substep']:.3g} s")
        axes[2].set_xlabel("t [s]")
        axes[2].set_ylabel("tip y [m]")
        axes[2].legend(fontsize=6)
        axes[2].grid(alpha=0.3)
        figure.suptitle("7x7 mass-spring with area constraint: error against substep and wall "
                        "time", fontsize=9)
        figure.tight_layout(rect=(0, 0.05, 1, 1))
        name = report.figure("validation_solid.png", figure, "1 rank", constrained[0]["command"])
        add(f"\n![solid]({name})\n")

    # Stiffness ---------------------------------------------------------------------
    records = results.get("stiffness", [])
    if records:
        add("## Stiffness sweep: automatic substeps\n")
        ok = [r for r in records if r.get("status") == 0]
        ks = [r["k"] for r in ok]
        figure, axes = plt.subplots(figsize=(6.4, 4))
        subs = [r["substeps"] for r in ok]
        walls = [r["wall"] for r in ok]
        stiff = [(k, s, w) for k, s, w in zip(ks, subs, walls) if s > 4]
        p_sub = slope([s[0] for s in stiff], [s[1] for s in stiff])
        p_wall = slope([s[0] for s in stiff], [s[2] for s in stiff])
        numbers["stiffness_substep_slope"] = p_sub
        numbers["stiffness_wall_slope"] = p_wall
        axes.loglog(ks, subs, "o-", label=f"substeps per step: slope {p_sub:.2f} (k > 1e4)")
        axes.loglog(ks, walls, "s-", label=f"loop wall time [s]: slope {p_wall:.2f} (k > 1e4)")
        if stiff:
            k0, s0 = stiff[-1][0], stiff[-1][1]
            axes.loglog(ks, [s0 * math.sqrt(k / k0) for k in ks], "k:", lw=0.8,
                        label=r"$\propto\sqrt{k}$")
        axes.set_xlabel("spring stiffness k [N/m]")
        axes.grid(alpha=0.3, which="both")
        axes.legend(fontsize=7)
        axes.set_title("7x7 body, automatic substeps: cost against stiffness", fontsize=9)
        figure.tight_layout(rect=(0, 0.04, 1, 1))
        name = report.figure("validation_stiffness.png", figure, "1 rank", records[-1]["command"])
        add(f"![stiffness]({name})\n")
        add(f"Every stiffness from {min(r['k'] for r in records):.0e} to "
            f"{max(r['k'] for r in records):.0e} N/m: "
            f"{sum(1 for r in records if r.get('status') == 0)} of {len(records)} ran to the end. "
            "Substeps grow like k^" f"{p_sub:.2f} once they exceed one per step; the wall time "
            f"like k^{p_wall:.2f} (the fixed cost per outer step dominates at low k).\n")

    # Box in flow --------------------------------------------------------------------
    box = results.get("box", {})
    if box:
        add("## Box in flow: centroid at the end time against resolution\n")
        records = [r for r in box["records"] if "centroid" in r]
        add("| l0 | outcome | wall [s] | centroid at end [m] | distance to finest [m] |")
        add("| --- | --- | --- | --- | --- |")
        finest = min(records, key=lambda r: r["spacing"]) if records else None
        for r in box["records"]:
            c = r.get("centroid")
            d = (math.dist(c, finest["centroid"]) if c and finest and r is not finest else math.nan)
            r["distance"] = d
            add(f"| {r['spacing']:.4g} | {short(r['outcome'])} | {r.get('wall', math.nan):.2f} | "
                f"{'—' if c is None else f'({c[0]:.4f}, {c[1]:.4f})'} | {d:.2e} |")
        coarse = [r for r in records if r is not finest and np.isfinite(r["distance"])]
        if len(coarse) >= 2:
            order = slope([r["spacing"] for r in coarse], [r["distance"] for r in coarse])
            add(f"\nObserved self-convergence order in l0 (centroid distance to the finest "
                f"run, {len(coarse)} coarser resolutions): {order:.2f}"
                + (" — the distances do not fall with l0: every resolution lands within "
                   f"{max(r['distance'] for r in coarse):.1e} m of the finest, below the "
                   "particle noise, so no order can be read off at this end time."
                   if order <= 0 else ".") + "\n")
        if len(coarse) >= 1:
            figure, axes = plt.subplots(figsize=(6, 4))
            axes.loglog([r["wall"] for r in coarse], [r["distance"] for r in coarse], "o-",
                        label=f"centroid distance to finest: slope "
                              f"{slope([r['wall'] for r in coarse], [r['distance'] for r in coarse]):.2f}")
            axes.set_xlabel("loop wall time [s]")
            axes.set_ylabel("|centroid - centroid(finest)| [m]")
            axes.grid(alpha=0.3, which="both")
            axes.legend(fontsize=7)
            figure.tight_layout(rect=(0, 0.04, 1, 1))
            name = report.figure("validation_box.png", figure,
                                 f"{study.args.ranks[-1]} ranks", coarse[0]["command"])
            add(f"\n![box]({name})\n")

    # Stability map --------------------------------------------------------------------
    # scripts/stability_map.py's block (the coupled bodies' map) is kept as it stands.
    coupled = coupled_stability_block(os.path.join(docs, "validation.md"))
    if study.table_rows or coupled:
        add("## Stability map\n")
    if study.table_rows:
        add("Each run under a timeout; 'ran to the end' means exit status 0 and finite fields "
            "in the last frame, 'stopped' quotes the one-line message of exit status 1.\n")
        add("| case | parameter | outcome | wall [s] | note |")
        add("| --- | --- | --- | --- | --- |")
        for case, parameter, record in study.table_rows:
            wall = record.get("wall", math.nan)
            add(f"| {case} | {parameter} | {record['outcome'].replace('|', '/')} | "
                f"{wall:.2f} | {record.get('note', '')} |")
        add("")
        numbers["stability_nan_without_message"] = sum(
            1 for _, _, r in study.table_rows if "NON-FINITE" in r["outcome"]
            or "without a message" in r["outcome"])
        numbers["stability_hung"] = sum(1 for _, _, r in study.table_rows
                                        if r["outcome"].startswith("hung"))
    if coupled:
        add(coupled + "\n")

    add("## Guards added with this report\n")
    add("- a fluid particle inside wall material (tank walls, wall boxes) stops the run: "
        "`parmps/run/guards.py`, `tests/test_guards.py`;\n"
        "- a mass-spring body that blew up (non-finite, area constraint lost beyond 10 %, "
        "a spring stretched beyond 20 × its rest length) stops the run with the step, in "
        "solid-only and coupled runs;\n"
        "- a fixed dt beyond the Courant limit stops with the limit (it did already; now "
        "also tested for the last good frame).\n")
    text = "\n".join(md) + "\n"
    path = os.path.join(docs, "validation.md")
    with open(path, "w") as handle:
        handle.write(text)
    report.files.append(path)
    summary = {"numbers": numbers, "machine": report.machine, "command": command,
               "results": strip_curves(results),
               "table": [{"case": c, "parameter": p, "outcome": r["outcome"],
                          "wall": r.get("wall")} for c, p, r in study.table_rows]}
    with open(os.path.join(docs, "validation.json"), "w") as handle:
        json.dump(summary, handle, indent=1, default=float)
    return report.files, numbers


def coupled_stability_block(path):
    """The block scripts/stability_map.py wrote into the report, markers included, or ''."""
    from stability_map import BEGIN, END
    if not os.path.exists(path):
        return ""
    text = open(path).read()
    if BEGIN not in text or END not in text:
        return ""
    return BEGIN + text.split(BEGIN, 1)[1].split(END, 1)[0] + END


def short(outcome, width=90):
    return outcome if len(outcome) <= width else outcome[:width - 1] + "…"


def strip_curves(results):
    drop = ("curve", "tip", "tip_time", "bottom_series", "bottom_times")
    out = {}
    for key, value in results.items():
        if isinstance(value, list):
            out[key] = [{k: v for k, v in item.items() if k not in drop}
                        if isinstance(item, dict) else item for item in value]
        else:
            out[key] = value
    return out


def dam_break_comment(records):
    one = sorted((r for r in records if r["ranks"] == 1), key=lambda r: r["m"])
    if len(one) < 2:
        return ""
    return (f"From a/{one[0]['m']} to a/{one[-1]['m']} the unshifted error goes from "
            f"{100 * one[0]['rms']:.1f} % to {100 * one[-1]['rms']:.1f} % at "
            f"{one[-1]['wall'] / max(one[0]['wall'], 1e-9):.0f} × the wall time: the "
            "simulated front leads the experiment by a nearly constant time, and refining "
            "l0 does not close the gap. With the best "
            f"constant delay (T ≈ {one[-1]['delay']:.2f}) the error is "
            f"{100 * one[-1]['rms_shifted']:.1f} % at a/{one[-1]['m']}.\n")


def scheme_verdict(records):
    hydro = {r["label"]: r for r in records if r["case"] == "hydrostatic" and "bottom_std" in r}
    dam = {}
    for r in records:
        if r["case"] == "dam_break" and "rms" in r:
            dam.setdefault(r["label"], []).append(r)
    lines = []
    if "density" in hydro and "default" in hydro:
        d, m = hydro["density"], hydro["default"]
        lines.append(f"Hydrostatic noise (bottom std): density {100 * d['bottom_std']:.2f} %, "
                     f"default {100 * m['bottom_std']:.2f} %; time-averaged error "
                     f"{100 * d['mean_error']:.2f} % against {100 * m['mean_error']:.2f} %; "
                     f"RMS speed at the end {d['speed_rms']:.3f} against "
                     f"{m['speed_rms']:.3f} m/s; wall {d['wall']:.1f} s against "
                     f"{m['wall']:.1f} s.")
    for label, items in dam.items():
        lines.append(f"Dam break, {label}: " + ", ".join(
            f"a/{r['m']} {100 * r['rms']:.1f} % ({100 * r['rms_shifted']:.1f} % delayed, "
            f"{r['wall']:.1f} s)" for r in items) + ".")
    return "\n".join(f"- {line}" for line in lines) + "\n" if lines else ""


PARTS = ("dam_break", "hydrostatic", "schemes", "solid", "stiffness", "stability", "box")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a few coarse points (tests)")
    parser.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--docs", default=None, help="where validation.md and the PNGs go")
    parser.add_argument("--work", default=None, help="where the runs' output goes")
    parser.add_argument("--only", nargs="+", default=None,
                        choices=PARTS)
    parser.add_argument("--report", action="store_true",
                        help="run nothing: rewrite the report from the sections in --work")
    args = parser.parse_args()
    args.docs = args.docs or os.path.join(ROOT, "out/study-quick" if args.quick else "docs")
    args.work = args.work or os.path.join(ROOT, "out", "study-quick-runs" if args.quick
                                          else "study-runs")
    command = "scripts/study.py" + (" --quick" if args.quick else "") + (
        " --ranks " + " ".join(map(str, args.ranks)) if args.ranks != [1, 2] else "") + (
        " --only " + " ".join(args.only) if args.only else "")
    study = Study(args)
    start = time.perf_counter()
    sections = os.path.join(args.work, "sections")
    os.makedirs(sections, exist_ok=True)
    for part in PARTS:
        if not args.report and (args.only is None or part in args.only):
            before = set(study.results)
            rows = len(study.table_rows)
            getattr(study, part)()
            saved = {"results": {k: v for k, v in study.results.items() if k not in before},
                     "rows": [list(row) for row in study.table_rows[rows:]]}
            with open(os.path.join(sections, part + ".json"), "w") as handle:
                json.dump(saved, handle, default=float)
    # The report merges every section run so far (--only reruns some of them).
    study.results, study.table_rows = {}, []
    for part in PARTS:
        path = os.path.join(sections, part + ".json")
        if os.path.exists(path):
            with open(path) as handle:
                saved = json.load(handle)
            study.results.update(saved["results"])
            study.table_rows.extend(tuple(row) for row in saved["rows"])
    files, numbers = write_report(study, args.docs, command)
    print(json.dumps({"files": files, "numbers": numbers,
                      "seconds": round(time.perf_counter() - start, 1)}, default=float))
    return 0


if __name__ == "__main__":
    sys.exit(main())
