#!/usr/bin/env python3
"""Write validation/rbc_stretch/sweep.toml: cases/rbc_stretch.toml's cell pulled through
every force of the Mills et al. (2004) record, one after the other.

Usage: python validation/rbc_stretch/make_sweep.py

Each level adds the step to the next force on both sides (a pair of [[body.load]] from
its start on, ramped over RAMP) and is held HOLD seconds; the metric (cell_stretch in
parmps/tools/analysis.py) reads the cell at the end of each hold. Everything else is the
case's own.
"""

import pathlib
import re

HERE = pathlib.Path(__file__).resolve().parent
ROOT = HERE.parents[1]
HOLD = 1.0e-3      # [s] per force: ramp and rest (the 193 pN pull rests within 1 ms from 0)
RAMP = 2.5e-4      # [s]


def forces():
    """The record's forces [N], zero left out."""
    lines = [line for line in (HERE / "mills_2004.csv").read_text().splitlines()
             if line and not line.startswith("#")][1:]
    return [float(line.split(",")[0]) * 1e-12 for line in lines if float(line.split(",")[0])]


def main():
    case = (ROOT / "cases" / "rbc_stretch.toml").read_text()
    body = case[:case.index("[[body.load]]")]
    levels = forces()
    body = re.sub(r"^title = .*$", 'title = "A red blood cell stretched by optical tweezers '
                  'through every force of Mills et al. (2004), each held to rest"', body,
                  count=1, flags=re.M)
    body = re.sub(r"^end = .*$", f"end = {HOLD * len(levels):.6g}               "
                  f"# [s]: {len(levels)} forces, {HOLD:g} s each", body, count=1, flags=re.M)
    lines = ["# Written by validation/rbc_stretch/make_sweep.py from cases/rbc_stretch.toml:",
             "# the same cell, every force of mills_2004.csv in turn.", body.rstrip(), ""]
    previous = 0.0
    for k, force in enumerate(levels):
        step = force - previous
        for side, sign in (("right", 1.0), ("left", -1.0)):
            lines += ["[[body.load]]", f'nodes = "{side}"', "within = 1.0e-6", "total = true",
                      f"force = [{sign * step:.6g}, 0.0, 0.0]   # to {force * 1e12:.0f} pN",
                      f"start = {k * HOLD:.6g}", f"ramp = {RAMP:g}", ""]
        previous = force
    (HERE / "sweep.toml").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
