#!/usr/bin/env python3
"""Write SPHERIC Test 2 built from surface meshes: ``cases/meshes/spheric_tank.stl`` (the
tank, an open surface: floor and four walls, facing in), ``cases/meshes/spheric_box.stl``
(the box on the floor, closed, facing out) and ``cases/dam_break_3d_meshed.toml`` (the
case of cases/dam_break_3d.toml with its ``[[tank]]`` and ``[[wall_box]]`` replaced by
``[[wall]]`` entries reading those files, and the force probe naming the meshed box).

The geometry is read from cases/dam_break_3d.toml itself (the published one), so the two
cases describe the same scene; the meshes are written by meshio, not by parmps.

Usage: python validation/dam_break_3d_meshed/make_case.py
"""

import pathlib
import re
import tomllib

import meshio
import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[2]
SOURCE = ROOT / "cases" / "dam_break_3d.toml"
MESHES = ROOT / "cases" / "meshes"
# A box's faces as outward quads (counter-clockwise seen from outside) of its corners
# numbered x + 2 y + 4 z; the last is the top.
QUADS = [(0, 2, 3, 1), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5), (4, 5, 7, 6)]


def box_mesh(lower, upper, open_top=False):
    """A box's corners and triangles: closed and facing out, or without its top and facing
    in (a tank: its water on the side the triangles face)."""
    corners = np.array([[(lower, upper)[(i >> a) & 1][a] for a in range(3)] for i in range(8)])
    quads = QUADS[:-1] if open_top else QUADS
    triangles = np.array([t for a, b, c, d in quads for t in ((a, b, c), (a, c, d))])
    return corners, (triangles[:, ::-1] if open_top else triangles)


def entry(pattern, text):
    """The one TOML table ``pattern`` matches in ``text`` (its header and keys)."""
    found = re.findall(pattern, text, flags=re.M)
    if len(found) != 1:
        raise SystemExit(f"{SOURCE}: expected one {pattern!r}, found {len(found)}")
    return found[0]


def main():
    text = SOURCE.read_text()
    case = tomllib.loads(text)
    (tank,), (box,) = case["tank"], case["wall_box"]
    MESHES.mkdir(exist_ok=True)
    for name, mesh in (("spheric_tank.stl", box_mesh(tank["lower"], tank["upper"], True)),
                       ("spheric_box.stl", box_mesh(box["lower"], box["upper"]))):
        meshio.write(MESHES / name, meshio.Mesh(mesh[0], [("triangle", mesh[1])]),
                     binary=False)
    tank_table = entry(r"^\[\[tank\]\]\n(?:\w+ = .*\n)+", text)
    box_table = entry(r"^\[\[wall_box\]\]\n(?:\w+ = .*\n)+", text)
    text = text.replace(tank_table, '[[wall]]                   # the tank: an open surface '
                        '(no roof), facing in\nname = "tank"\nmesh = "meshes/spheric_tank.stl"'
                        '\n')
    text = text.replace(box_table, '[[wall]]                   # the box on the floor\n'
                        'name = "box"\nmesh = "meshes/spheric_box.stl"\nfluid = "outside"\n')
    text = text.replace(entry(r"^wall_box = 0\n", text), 'wall = "box"\n')
    header = ("# Written by validation/dam_break_3d_meshed/make_case.py from "
              "cases/dam_break_3d.toml:\n# the same scene with its tank and box read from "
              "surface meshes (cases/meshes/).\n")
    (ROOT / "cases" / "dam_break_3d_meshed.toml").write_text(header + text)


if __name__ == "__main__":
    main()
