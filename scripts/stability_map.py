#!/usr/bin/env python3
"""Stability map of the coupled bodies (issue 12, item 6): which runs reach their end.

    scripts/stability_map.py [--ranks 1] [--box-end 0.3] [--gate-end 0.15]
                             [--only box gate] [--work out/stability-map] [--docs docs]

- box_in_flow (cases/box_in_flow.toml) at solid/fluid density 0.01, 0.1, 0.3, 1 and 10
  (body.0.density) and inflow 1, 2, 5 and 10 x U0: the inlet, the initial water and the
  outflow buffer all scaled, as the case sets them (its outflow buffer leaves at the
  inflow's speed, so outflow matches inflow);
- the elastic gate (cases/elastic_gate.toml) at Young's modulus 1, 3, 10, 30 and 100 MPa.

Every run goes through the command line a user types, under a timeout (scripts/study.py's
``run``). 'ran to the end' is exit status 0 with finite fields in the last frame;
'stopped' quotes the one-line message of exit status 1; a run that ends otherwise (NaN
without a message, a crash, a hang) is counted as such. The map is written to
``DOCS/stability_map.json`` and as markdown into ``DOCS/validation.md``, between the
markers of its "Stability map" section (scripts/study.py keeps that block when it rewrites
the report). Runs of one part are saved in WORK/<part>.json, so ``--only`` reruns a part
and the report merges both.
"""

import argparse
import json
import math
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from parmps import validation
from parmps.tools import analysis
from parmps.validation import launch


def run(case, out, sets=(), end_time=None, petsc=(), ranks=1, timeout=600):
    """One run through the package's launcher, from the repository."""
    return launch.run(case, out, sets, end_time, petsc, ranks, timeout, root=ROOT, cwd=ROOT)


BOX_DENSITY_RATIOS = (0.01, 0.1, 0.3, 1.0, 10.0)
BOX_INFLOW_FACTORS = (1.0, 2.0, 5.0, 10.0)
GATE_MODULI = (1.0e6, 3.0e6, 1.0e7, 3.0e7, 1.0e8)
# A box run that stops is run again with time.dt_max divided by this.
RETRY_STEP_DIVISOR = 4

BEGIN = "<!-- stability-map: scripts/stability_map.py writes from here -->"
END = "<!-- stability-map: to here -->"


def inflow_sets(case, factor):
    """Overrides that scale box_in_flow's inflow by ``factor``: the inlet, every block of
    initial water (so the start is not impulsive) and the outflow buffer's speed."""
    sets = []
    for section in ("inlet", "fluid_block", "outlet"):
        for k, spec in enumerate(case[section]):
            v = spec["velocity"]
            sets.append(f"{section}.{k}.velocity=[{factor * v[0]:.10g}, {factor * v[1]:.10g}]")
    return sets


def outcome_record(record, body, check=None):
    """What a row shows: the outcome and, for a run with output, the body's largest area
    error and the time reached."""
    out = {key: record.get(key) for key in ("command", "status", "outcome", "message",
                                            "wall", "end", "elapsed")}
    path = record["result"]
    if os.path.exists(path):
        try:
            series = analysis.solid_series(path, body)
            error = np.abs(series["volume_error"])
            out["volume_error"] = float(np.nanmax(error)) if len(error) else math.nan
        except (KeyError, OSError):
            pass
        if check is not None:
            try:
                measured = analysis.elastic_gate(path, None, **check)
                out.update(dx_max=measured["dx_max"], t_dx_max=measured["t_dx_max"],
                           dy_max=measured["dy_max"], crossings=measured["crossings"])
            except (KeyError, OSError, ValueError):
                pass
    return out


def box_part(args):
    check = validation.load("box_in_flow")
    case = check.case()
    rho = case["fluid"]["density"]
    u0 = abs(case["inlet"][0]["velocity"][0] or case["inlet"][0]["velocity"][1])
    rows = []
    for ratio in BOX_DENSITY_RATIOS:
        for factor in BOX_INFLOW_FACTORS:
            sets = [f"body.0.density={ratio * rho:.10g}", "time.output_interval=0.05"]
            sets += inflow_sets(case, factor)
            out = os.path.join(args.work, "box", f"rho{ratio:g}_u{factor:g}")
            record = run(check.case_path, out, sets, args.box_end, ranks=args.ranks,
                         timeout=args.timeout)
            row = outcome_record(record, case["body"][0]["name"])
            row.update(density_ratio=ratio, inflow_factor=factor, inflow=factor * u0,
                       end_time=args.box_end)
            if row["outcome"] != "ran to the end":
                # Does a shorter step hold it? (the lag of an explicit exchange grows per step)
                dt_max = case["time"]["dt_max"] / RETRY_STEP_DIVISOR
                retry = run(check.case_path, out + "_short_dt",
                            sets + [f"time.dt_max={dt_max:.10g}"], args.box_end,
                            ranks=args.ranks, timeout=args.timeout)
                row["retry"] = dict(outcome_record(retry, case["body"][0]["name"]), dt_max=dt_max)
            print(f"box density {ratio:g}, {factor:g} U0: {row['outcome']} "
                  f"({row.get('wall') or math.nan:.1f} s)", flush=True)
            rows.append(row)
    return {"u0": u0, "rows": rows}


def gate_part(args):
    check = validation.load("elastic_gate")
    rows = []
    for modulus in GATE_MODULI:
        out = os.path.join(args.work, "gate", f"E{modulus:g}")
        sets = [f"body.0.youngs_modulus={modulus:.10g}", "time.output_interval=0.02"]
        record = run(check.case_path, out, sets, args.gate_end, ranks=args.ranks,
                     timeout=args.timeout)
        metric = {key: check.metric[key] for key in ("probe", "check", "body")}
        row = outcome_record(record, check.metric["body"], metric)
        row.update(youngs_modulus=modulus, end_time=args.gate_end)
        print(f"gate E = {modulus:g} Pa: {row['outcome']} ({row.get('wall') or math.nan:.1f} s)",
              flush=True)
        rows.append(row)
    return {"rows": rows}


def cell(row):
    """A short table cell: the outcome, the wall time and the area error."""
    wall = row.get("wall")
    wall_text = f", {wall:.0f} s" if wall is not None else ""
    error = row.get("volume_error")
    error_text = f", area {error:.0e}" if error is not None and math.isfinite(error) else ""
    outcome = row["outcome"]
    if outcome == "ran to the end":
        return f"ran{wall_text}{error_text}"
    retry = ""
    if row.get("retry"):
        again = row["retry"]
        retry = (f"; with time.dt_max = {again['dt_max']:g} s: "
                 + ("ran" if again["outcome"] == "ran to the end" else
                    f"**stopped** at t = {again.get('end') or 0:.3g} s [{again['note']}]") +
                 (f", {again['wall']:.0f} s" if again.get("wall") is not None else ""))
    if outcome.startswith("stopped"):
        return (f"**stopped** at t = {row.get('end') or 0:.3g} s [{row['note']}]{wall_text}"
                f"{retry}")
    return f"**{outcome.split(':')[0]}** [{row['note']}]"


def markdown(parts, command):
    lines = [BEGIN, "", "### Coupled bodies: box in flow and elastic gate (issue 12)", "",
             f"Generated by `{command}` (the default coupling, `implicit_pressure`; "
             f"{parts.get('ranks', 1)} rank(s) a run, on the shared 2-core machine). A cell "
             "says whether the run reached its end time, its loop wall time and the body's "
             "largest area error |A - A0|/A0; a stopped run gives the time it stopped at and "
             "a note quoting its message below. The box rows of the table above are the "
             "earlier design's (the weak coupling, to 0.2 s, the outflow buffer left at U0); "
             "this map supersedes them.", ""]
    notes = []

    def noted(row):
        for run_row in (row, row.get("retry")):
            if run_row and run_row["outcome"] != "ran to the end":
                notes.append(run_row["outcome"].replace("|", "/"))
                run_row["note"] = str(len(notes))
        return row

    box = parts.get("box")
    if box:
        rows = box["rows"]
        end = rows[0]["end_time"]
        factors = sorted({r["inflow_factor"] for r in rows})
        ratios = sorted({r["density_ratio"] for r in rows})
        lines.append(f"**box_in_flow** (`cases/box_in_flow.toml`, U0 = {box['u0']:g} m/s) to "
                     f"t = {end:g} s: solid/fluid density (rows) against inflow (columns)")
        lines.append("")
        lines.append("| density ratio | " + " | ".join(f"{f:g} × U0 = {f * box['u0']:g} m/s"
                                                        for f in factors) + " |")
        lines.append("| --- |" + " --- |" * len(factors))
        by_key = {(r["density_ratio"], r["inflow_factor"]): r for r in rows}
        for ratio in ratios:
            cells = [cell(noted(by_key[(ratio, f)])) if (ratio, f) in by_key else "—"
                     for f in factors]
            lines.append(f"| {ratio:g} | " + " | ".join(cells) + " |")
        lines.append("")
    gate = parts.get("gate")
    if gate:
        rows = gate["rows"]
        end = rows[0]["end_time"]
        lines.append(f"**elastic gate** (`cases/elastic_gate.toml`) to t = {end:g} s against "
                     "Young's modulus (ν = 0.4 and the rest of the case unchanged)")
        lines.append("")
        lines.append("| E [MPa] | outcome | largest tip opening dx [mm] (at t [s]) | "
                     "fluid crossings | largest area error |")
        lines.append("| --- | --- | --- | --- | --- |")
        for row in rows:
            opening = (f"{1e3 * row['dx_max']:.1f} ({row['t_dx_max']:.3f})"
                       if row.get("dx_max") is not None else "—")
            error = row.get("volume_error")
            lines.append(f"| {row['youngs_modulus'] / 1e6:g} | {cell(noted(row))} | {opening} | "
                         f"{row.get('crossings', '—')} | "
                         f"{'—' if error is None else f'{error:.1e}'} |")
        lines.append("")
    if notes:
        lines.append("Messages of the runs that stopped:")
        lines.append("")
        lines += [f"{k}. {text}" for k, text in enumerate(notes, 1)]
        lines.append("")
    every = [r for part in ("box", "gate") if parts.get(part) for r in parts[part]["rows"]]
    silent = [r for r in every if r["outcome"] != "ran to the end"
              and not r["outcome"].startswith("stopped")]
    lines.append(f"{len(every)} runs: {sum(r['outcome'] == 'ran to the end' for r in every)} "
                 f"ran to the end, {sum(r['outcome'].startswith('stopped') for r in every)} "
                 f"stopped with a message, {len(silent)} ended otherwise (NaN without a "
                 "message, a crash or a hang).")
    retries = [r["retry"] for r in every if r.get("retry")]
    if retries:
        lines[-1] += (f" The {len(retries)} that stopped, run again with the shorter step: "
                      f"{sum(r['outcome'] == 'ran to the end' for r in retries)} ran to the "
                      f"end, {sum(r['outcome'].startswith('stopped') for r in retries)} stopped "
                      "with a message.")
    lines += ["", END]
    return "\n".join(lines)


def splice(path, block):
    """Put ``block`` into the report at its markers, or at the end of its Stability map
    section (before the next '## ' heading) the first time."""
    text = open(path).read() if os.path.exists(path) else ""
    if BEGIN in text and END in text:
        head, rest = text.split(BEGIN, 1)
        text = head + block + rest.split(END, 1)[1]
    elif "## Stability map" in text:
        head, rest = text.split("## Stability map", 1)
        at = rest.find("\n## ")
        at = len(rest) if at < 0 else at
        text = head + "## Stability map" + rest[:at].rstrip("\n") + "\n\n" + block + "\n" + \
            rest[at:]
    else:
        text = text.rstrip("\n") + "\n\n## Stability map\n\n" + block + "\n"
    with open(path, "w") as handle:
        handle.write(text)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ranks", type=int, default=1)
    parser.add_argument("--box-end", type=float, default=0.3)
    parser.add_argument("--gate-end", type=float, default=0.15)
    parser.add_argument("--timeout", type=float, default=1800)
    parser.add_argument("--only", nargs="+", choices=("box", "gate"), default=("box", "gate"))
    parser.add_argument("--work", default=os.path.join(ROOT, "out", "stability-map"))
    parser.add_argument("--docs", default=os.path.join(ROOT, "docs"))
    parser.add_argument("--report", action="store_true",
                        help="run nothing: rewrite the table from WORK's saved parts")
    args = parser.parse_args()
    command = (f"scripts/stability_map.py --ranks {args.ranks} --box-end {args.box_end:g} "
               f"--gate-end {args.gate_end:g}")
    os.makedirs(args.work, exist_ok=True)
    start = time.perf_counter()
    for name, part in (("box", box_part), ("gate", gate_part)):
        if not args.report and name in args.only:
            with open(os.path.join(args.work, name + ".json"), "w") as handle:
                json.dump(part(args), handle, indent=1, default=float)
    parts = {"ranks": args.ranks}
    for name in ("box", "gate"):
        path = os.path.join(args.work, name + ".json")
        if os.path.exists(path):
            with open(path) as handle:
                parts[name] = json.load(handle)
    block = markdown(parts, command)
    splice(os.path.join(args.docs, "validation.md"), block)
    with open(os.path.join(args.docs, "stability_map.json"), "w") as handle:
        json.dump({"command": command, **parts}, handle, indent=1, default=float)
    print(json.dumps({"seconds": round(time.perf_counter() - start, 1),
                      "report": os.path.join(args.docs, "validation.md")}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
