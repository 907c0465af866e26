#!/usr/bin/env python3
"""The pressure schemes side by side: still tank, Lobovsky dam break, coupled scenes, cost.

    scripts/compare_schemes.py [--schemes LABEL ...] [--parts PART ...]
                               [--lobovsky-spacing L0] [--ranks N] [--out DIR]

Each scheme is a set of case overrides (parmps/validation/presets.py). Each part runs the
scheme through one measurement and appends one JSON line to DIR/results.jsonl
(default out/schemes/); a scheme and part already there is not run again, so an
interrupted comparison continues where it stopped. The parts:

- ``tank1cm``, ``tank5mm``: cases/hydrostatic.toml for 2 s at l0 = 1 cm and
  5 mm, measured after 0.5 s as validation/hydrostatic/ says (RMS, bottom mean,
  bottom noise, column height drift; relative to rho g H);
- ``lobovsky``: cases/dam_break_lobovsky.toml to t sqrt(g/H) = 7 at
  --lobovsky-spacing, P1-P3 arrival and mean error (validation/dam_break_lobovsky/);
- ``box``: cases/box_in_flow.toml to 0.6 s: the cup's depth (bend) and area error;
- ``membrane``: cases/membrane_tube.toml to 1.5 s: the mid-point's largest
  inward and outward travel and the tube's area error;
- ``cost``: python -m parmps bench at about 10k particles on 1 rank, us per particle-step.

Then it prints the table (markdown) of every line in the file.
"""

import argparse
import json
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

from parmps.validation import launch
from parmps.validation.presets import COMPARED, SCHEMES

PARTS = ("tank1cm", "tank5mm", "lobovsky", "box", "membrane", "cost")


def run_parmps(case, directory, overrides, end_time, ranks, extra=()):
    """Run parmps through the package's launcher; returns (exit status, result path)."""
    record = launch.run(os.path.join(ROOT, case), directory, list(overrides) + list(extra),
                        end_time, ranks=ranks, timeout=None, root=ROOT, cwd=ROOT)
    return record["status"], os.path.join(directory, "result.h5")


def summary(result):
    from parmps.tools import analysis
    return analysis.run_summary(result) if os.path.isfile(result) else {}


def tank(label, overrides, spacing, directory, ranks):
    from parmps import validation
    check = validation.load("hydrostatic")
    status, result = run_parmps(check.case_path, directory, overrides, check.run["end_time"],
                                ranks, [f"particles.spacing={spacing!r}",
                                        "time.output_interval=0.01"])
    record = summary(result)
    record["status"] = status
    if status == 0:
        record.update(measure_tank(result))
    return record


def measure_tank(result):
    from parmps import validation
    measured = validation.load("hydrostatic").measure(result)
    return {key: measured[key] for key in
            ("rms", "bottom", "bottom_std", "height_drift", "speed_rms")}


def lobovsky(label, overrides, spacing, directory, ranks):
    from parmps import validation
    check = validation.load("dam_break_lobovsky")
    end, sets = check.run_arguments([f"particles.spacing={spacing!r}"])
    status, result = run_parmps(check.case_path, directory, overrides, end, ranks, sets)
    record = summary(result)
    record["status"] = status
    if os.path.isfile(result):
        measured = check.measure(result)
        for name in check.tolerance["judged"]:
            row = measured[name]
            record[name] = {"arrival": row["arrival_error"], "mean": row["mean_error"],
                            "peak": row["peak"], "peak_measured": row["peak_measured"]}
    return record


def box(label, overrides, spacing, directory, ranks):
    import numpy as np

    from parmps import open_result
    from parmps.tools import analysis
    status, result = run_parmps("cases/box_in_flow.toml", directory, overrides, 0.6, ranks,
                                ["time.output_interval=0.6"])
    record = summary(result)
    record["status"] = status
    if os.path.isfile(result):
        case = analysis.result_case(result)
        record["volume_error"] = analysis.volume_error(result, case)["volume_error"]
        with open_result(result) as read:
            nodes = read.frames[-1].bodies["box"]["position"]
        record["bend"] = float(analysis.lattice_bend(nodes, case["body"][0]))
        record["bend_time"] = float(np.round(case["time"]["end"], 6))
    return record


def membrane(label, overrides, spacing, directory, ranks):
    import numpy as np

    from parmps import open_result
    from parmps.tools import analysis
    status, result = run_parmps("cases/membrane_tube.toml", directory, overrides, 1.5, ranks,
                                ["time.output_interval=0.01"])
    record = summary(result)
    record["status"] = status
    if os.path.isfile(result):
        case = analysis.result_case(result)
        record["volume_error"] = analysis.volume_error(result, case)["volume_error"]
        with open_result(result) as read:
            middle = [frame.bodies["membrane"]["position"][19, 1] for frame in read.frames]
        travel = np.asarray(middle) - middle[0]
        record["inward"] = float(-travel.min())
        record["outward"] = float(travel.max())
    return record


def cost(label, overrides, spacing, directory, ranks):
    command = [sys.executable, "-m", "parmps", "bench", "--particles", "10000", "--steps", "20",
               "--warmup", "5"]
    command += [word for override in overrides for word in ("--set", override)]
    _, output, _, _ = launch.execute(command, timeout=None, cwd=ROOT, spin=True)
    lines = [json.loads(line) for line in output.splitlines() if line.startswith("{")]
    if not lines or "error" in lines[-1]:
        return {"status": 1}
    return {"status": 0, "us_per_particle_step": lines[-1]["us_per_particle_step"],
            "particles": lines[-1]["particles"]}


MEASURE = {"tank1cm": lambda *a: tank(*a[:2], 0.01, *a[3:]),
           "tank5mm": lambda *a: tank(*a[:2], 0.005, *a[3:]),
           "lobovsky": lobovsky, "box": box, "membrane": membrane, "cost": cost}


def percent(value, digits=1):
    return "—" if value is None else f"{100 * value:+.{digits}f}"


def table(records):
    """Markdown table: one row per scheme, the parts' figures side by side."""
    by_scheme = {}
    for record in records:
        by_scheme.setdefault(record["scheme"], {})[record["part"]] = record
    lines = ["| scheme | tank 1 cm: RMS / bottom / noise / drift (%) | tank 5 mm: RMS / bottom / "
             "noise / drift (%) | Lobovsky P1/P2/P3 arrival | P1/P2/P3 mean (%) | "
             "box bend (mm), area error | membrane in/out (mm) | us per particle-step |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]

    def tank_cell(record):
        if record is None:
            return "—"
        if record.get("status"):
            return f"stopped at {record.get('end', 0):.2f} s"
        return (f"{100 * record['rms']:.2f} / {percent(record['bottom'], 2)} / "
                f"{100 * record['bottom_std']:.1f} / {percent(record['height_drift'], 2)}")

    for label in SCHEMES:
        parts = by_scheme.get(label)
        if not parts:
            continue
        lob = parts.get("lobovsky")
        if lob and "P1" in lob:
            stopped = "" if lob["status"] == 0 else f" (stopped at {lob.get('end', 0):.2f} s)"
            arrival = " / ".join(f"{lob[n]['arrival']:+.3f}" for n in ("P1", "P2", "P3"))
            mean = " / ".join(percent(lob[n]["mean"], 0) for n in ("P1", "P2", "P3")) + stopped
        else:
            arrival = mean = "—"
        b = parts.get("box")
        box_cell = ("—" if b is None or "bend" not in b else
                    f"{1000 * b['bend']:.1f}, {b['volume_error']:.1e}"
                    + ("" if b["status"] == 0 else f" (stopped at {b.get('end', 0):.2f} s)"))
        m = parts.get("membrane")
        membrane_cell = ("—" if m is None or "inward" not in m else
                         f"{1000 * m['inward']:.1f} / {1000 * m['outward']:.1f}"
                         + ("" if m["status"] == 0 else f" (stopped at {m.get('end', 0):.2f} s)"))
        c = parts.get("cost")
        cost_cell = "—" if c is None or c.get("status") else f"{c['us_per_particle_step']:.2f}"
        lines.append(f"| {label} | {tank_cell(parts.get('tank1cm'))} | "
                     f"{tank_cell(parts.get('tank5mm'))} | {arrival} | {mean} | {box_cell} | "
                     f"{membrane_cell} | {cost_cell} |")
    return "\n".join(lines)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--schemes", nargs="+", default=list(COMPARED), choices=list(SCHEMES),
                        metavar="LABEL")
    parser.add_argument("--parts", nargs="+", default=list(PARTS), choices=PARTS)
    parser.add_argument("--lobovsky-spacing", type=float, default=0.01)
    parser.add_argument("--ranks", type=int, default=1)
    parser.add_argument("--out", default=os.path.join(ROOT, "out", "schemes"))
    parser.add_argument("--table", action="store_true", help="only print the table")
    parser.add_argument("--remeasure", action="store_true",
                        help="measure the stored still-tank results again (after a change of "
                             "the metric) and rewrite their lines")
    parser.add_argument("--write", metavar="MARKDOWN",
                        help="also write the table with its commands to this file "
                             "(docs/validation_schemes.md)")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    store = os.path.join(args.out, "results.jsonl")
    records = []
    if os.path.isfile(store):
        with open(store) as handle:
            records = [json.loads(line) for line in handle if line.strip()]
    if args.remeasure:
        for record in records:
            if record["part"].startswith("tank") and record["status"] == 0:
                slug = "".join(ch if ch.isalnum() else "_" for ch in record["scheme"])
                record.update(measure_tank(os.path.join(args.out, f"{record['part']}_{slug}",
                                                        "result.h5")))
        with open(store, "w") as handle:
            handle.writelines(json.dumps(record) + "\n" for record in records)
        args.table = True
    done = {(r["scheme"], r["part"]) for r in records}
    if not args.table:
        for part in args.parts:
            for label in args.schemes:
                if (label, part) in done:
                    continue
                slug = "".join(ch if ch.isalnum() else "_" for ch in label)
                directory = os.path.join(args.out, f"{part}_{slug}")
                record = MEASURE[part](label, SCHEMES[label], args.lobovsky_spacing,
                                       directory, args.ranks)
                record.update({"scheme": label, "part": part, "set": SCHEMES[label],
                               "ranks": args.ranks})
                if part == "lobovsky":
                    record["spacing"] = args.lobovsky_spacing
                records.append(record)
                with open(store, "a") as handle:
                    handle.write(json.dumps(record) + "\n")
                print(json.dumps(record), flush=True)
    print(table(records))
    if args.write:
        write_report(args.write, records)
    return 0


def write_report(path, records):
    """The table, what each column is and the commands that give it."""
    import platform
    spacing = sorted({r["spacing"] for r in records if r["part"] == "lobovsky"})
    text = f"""# Pressure schemes side by side

Generated by `scripts/compare_schemes.py --write {os.path.relpath(path, ROOT)}` from
`out/schemes/results.jsonl` (machine: {platform.machine()}, {os.cpu_count()} cores, shared with
other runs; wall times are loop times). The schemes (docs/design.md §1.4) and their overrides
are the `SCHEMES` table of parmps/validation/presets.py; MPS is the original scheme and the default before this
comparison (density source with the number density n, standard Laplacian, minimum-pressure
gradient); the default now is "MPS (smooth n) + GC", the density source measured with a smooth
sum (Wendland's C2 on the number density's radius) and the corrected gradient. Before it came
"MPS + GC" (the same with n) and, for a while, "mixed (γ 0.1) + GC", which the Lobovsky case
sets for itself: it was not stable enough to be the default (README "Pressure schemes"). The
membrane tube's own case sets the mixed source, so its "MPS" row is mixed (γ 0.01) with the
minimum gradient. The rows were measured on different days (the wall times are not comparable).

- **Still tank** (`cases/hydrostatic.toml`, 2 s, frames every 0.01 s, measured from 0.5 s as
  `validation/hydrostatic/` says), in % of rho g H: RMS over the fluid of the time-averaged
  error / the bottom row's time-averaged error / the bottom row's noise (standard deviation over
  frames) / the column's mean height 2<y> averaged over the window against its initial value.
  Targets (issue): RMS <= 1, bottom within ±0.5, noise <= 3, height within ±0.3.
- **Lobovsky** (`cases/dam_break_lobovsky.toml` at l0 = {", ".join(f"{1000 * s:g} mm" for s in spacing)},
  to t sqrt(g/H) = 7): P1/P2/P3 impact arrival minus the experiment's in t sqrt(g/H) (target
  ±0.1) and mean over 3-6 relative to the experiment's (target ±15 %).
- **Box in flow** (`cases/box_in_flow.toml` to 0.6 s): the cup's depth and the largest area error.
- **Membrane tube** (`cases/membrane_tube.toml` to 1.5 s): the mid-point's largest inward and
  outward travel.
- **Cost**: `scripts/bench.py --particles 10000 --set ...` on 1 rank, a single run on a shared
  machine: indicative; the default's cost is measured in paired runs (README).

{table(records)}
"""
    with open(path, "w") as handle:
        handle.write(text)


if __name__ == "__main__":
    sys.exit(main())
