"""Run-time checks (parmps.checks): fluid crossing a thin body's mid-line, counted every step;
and the displacement probe that follows a body's nodes."""

import numpy as np
import pytest

from conftest import error_lines, run_parmps
from parmps import open_result, schema
from parmps.checks import CHECKS
from parmps.checks.crossing import count_crossings, lattice_mid_line, mid_line_sides
from parmps.errors import CaseError
import tomllib

# A vertical gate of 4 x 11 nodes at x = 0..0.03, y = 0..0.1: mid-line x = 0.015.
GATE = np.column_stack([np.tile(np.arange(4) * 0.01, 11), np.repeat(np.arange(11) * 0.01, 4)])
BAND = 0.015 + 0.02


def test_mid_line_of_a_lattice_runs_along_its_longer_side():
    line = lattice_mid_line(GATE, 4, 11)
    assert line.shape == (11, 2)
    assert np.allclose(line[:, 0], 0.015) and np.allclose(line[:, 1], np.arange(11) * 0.01)
    lying = lattice_mid_line(GATE[:, ::-1].copy(), 11, 4)  # the same lattice on its side
    assert np.allclose(lying[:, 1], 0.015)


def test_sides_beside_beyond_the_ends_and_outside_the_band():
    line = lattice_mid_line(GATE, 4, 11)
    points = [[-0.005, 0.05], [0.035, 0.05],    # beside, either side
              [-0.005, -0.001], [0.035, 0.101],  # beyond the tip and beyond the top
              [-0.03, 0.05]]                     # farther than the band
    sides = mid_line_sides(points, line, BAND)
    assert sides[0] == -sides[1] and abs(sides[0]) == 1
    assert list(sides[2:]) == [0, 0, 0]


def _count(path, line):
    """Crossings along a particle's path (one position a step)."""
    total, previous = 0, (np.zeros(0, np.int64), np.zeros(0, np.int8))
    for point in path:
        side = mid_line_sides([point], line, BAND)
        ids, sides = np.array([7])[side != 0], side[side != 0]
        total += count_crossings(*previous, ids, sides)
        previous = (ids, sides)
    return total


def test_a_path_through_the_gate_counts_and_one_round_its_free_end_does_not():
    line = lattice_mid_line(GATE, 4, 11)
    through = [[x, 0.05] for x in np.linspace(-0.01, 0.04, 21)]  # steps of 2.5 mm
    assert _count(through, line) == 1
    # Down the upstream side, under the tip, up the downstream side, in steps of <= 2.5 mm.
    down = [[-0.005, y] for y in np.linspace(0.05, -0.005, 23)]
    under = [[x, -0.005] for x in np.linspace(-0.005, 0.035, 17)]
    up = [[0.035, y] for y in np.linspace(-0.005, 0.05, 23)]
    assert _count(down + under + up, line) == 0


def test_crossings_are_counted_per_particle_by_id():
    before_ids, before_sides = np.array([3, 5, 9]), np.array([1, -1, 1], np.int8)
    # 5 crossed, 3 stayed, 9 left the band, 11 arrived.
    now_ids, now_sides = np.array([11, 5, 3]), np.array([-1, 1, 1], np.int8)
    assert count_crossings(before_ids, before_sides, now_ids, now_sides) == 1


CASE = """
[domain]
lower = [-0.1, -0.1]
upper = [0.3, 0.3]
[particles]
spacing = 0.01
[[fluid_block]]
lower = [0.0, 0.0]
upper = [0.1, 0.1]
[[tank]]
lower = [0.0, 0.0]
upper = [0.2, 0.2]
[time]
end = 0.01
[[body]]
name = "gate"
nx = 3
ny = 5
spacing = 0.01
lower = [0.105, 0.005]
density = 1000.0
stiffness = 100.0
"""

BAD_CHECKS = {
    "unknown body": ('kind = "body_crossing"\nbody = "flap"', "check[0].body 'flap' is not a body"),
    "unknown kind": ('kind = "leak"\nbody = "gate"', "check[0].kind"),
    "no body": ('kind = "body_crossing"', "check[0].body"),
}


@pytest.mark.parametrize("label", sorted(BAD_CHECKS))
def test_bad_check_is_one_line_naming_the_key(label):
    body, message = BAD_CHECKS[label]
    with pytest.raises(CaseError) as caught:
        schema.validate(tomllib.loads(CASE + "\n[[check]]\n" + body + "\n"))
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_registry_names_what_the_schema_accepts():
    assert set(schema.SECTIONS["check"].keys["kind"].choices) == set(CHECKS)


def test_a_check_on_the_command_line_exits_2_with_one_line(tmp_path):
    path = tmp_path / "case.toml"
    path.write_text(CASE + '\n[[check]]\nkind = "body_crossing"\nbody = "flap"\n')
    result = run_parmps([path, "-o", tmp_path / "out", "--check"], timeout=60)
    assert result.returncode == 2
    lines = error_lines(result.stderr)
    assert len(lines) == 1 and "check[0].body 'flap'" in lines[0]


BAD_DISPLACEMENT = {
    "no nodes": ('name = "tip"\nkind = "displacement"\nbody = "gate"',
                 "missing key 'probe[0] 'tip'.nodes'"),
    "node out of range": ('name = "tip"\nkind = "displacement"\nbody = "gate"\nnodes = [15]',
                          "probe[0] 'tip'.nodes has 15, but body 'gate' has 15 nodes"),
    "no body": ('name = "tip"\nkind = "displacement"\nnodes = [0]',
                "missing key 'probe[0] 'tip'.body'"),
}


@pytest.mark.parametrize("label", sorted(BAD_DISPLACEMENT))
def test_bad_displacement_probe_is_one_line_naming_the_key(label):
    body, message = BAD_DISPLACEMENT[label]
    with pytest.raises(CaseError) as caught:
        schema.validate(tomllib.loads(CASE + "\n[[probe]]\n" + body + "\n"))
    assert message in str(caught.value)
    assert "\n" not in str(caught.value)


def test_displacement_probe_follows_the_nodes_and_the_check_is_in_the_output(tmp_path):
    """The gate of CASE, soft and sunk by the water's push: the probe's last row is the
    tip nodes' mean displacement in the last frame (to rounding), and /checks holds one
    row a step."""
    path = tmp_path / "case.toml"
    path.write_text(CASE + '\n[[probe]]\nname = "tip"\nkind = "displacement"\nbody = "gate"\n'
                    'nodes = [0, 1, 2]\n\n[[check]]\nkind = "body_crossing"\nbody = "gate"\n')
    result = run_parmps([path, "-o", tmp_path / "out"], timeout=300)
    assert result.returncode == 0, result.stderr
    with open_result(tmp_path / "out") as run:
        value = run.probes["tip"].value[-1]
        position = run.frames[-1].bodies["gate"]["position"][:3].mean(axis=0)
        rest = np.array([0.115, 0.005])
        assert np.allclose(value, position - rest, rtol=0, atol=1e-12)
        assert np.abs(run.probes["tip"].value).max() > 0.0
        checks = run.checks["body_crossing_gate"]
        assert len(checks.time) == len(run.diagnostics.time)
        assert checks.total[-1] == checks.crossings.sum()


def test_check_and_displacement_go_on_after_a_restart_without_repeating_rows(tmp_path):
    """The check's rows, its total and its (id, side) record, and the displacement probe's
    rows, continue through a checkpoint (1 rank, then 2) as in the uninterrupted run."""
    path = tmp_path / "case.toml"
    path.write_text(CASE + '\n[[probe]]\nname = "tip"\nkind = "displacement"\nbody = "gate"\n'
                    'nodes = [0, 1, 2]\n\n[[check]]\nkind = "body_crossing"\nbody = "gate"\n')
    tight = ["-pressure_ksp_rtol", "1e-12"]
    whole, split = tmp_path / "whole", tmp_path / "split"
    for args, ranks in (([path, "-o", whole, "--end-time", "0.02"], 1),
                        ([path, "-o", split, "--end-time", "0.01"], 1),
                        (["--restart", split, "--end-time", "0.02"], 2)):
        result = run_parmps(args + tight, ranks=ranks, timeout=300)
        assert result.returncode == 0, result.stderr[-3000:]
    rows = {}
    for name, out in (("whole", whole), ("split", split)):
        with open_result(out) as run:
            check = run.checks["body_crossing_gate"]
            rows[name] = (check.time, check.total, run.probes["tip"].value)
    np.testing.assert_allclose(rows["split"][0], rows["whole"][0], rtol=1e-12)
    np.testing.assert_array_equal(rows["split"][1], rows["whole"][1])
    np.testing.assert_allclose(rows["split"][2], rows["whole"][2], rtol=0, atol=1e-9)
