"""Bad input: one line on stderr naming the problem, exit status 2, no traceback, no hang."""

import pytest

from conftest import CASES, error_lines, run_parmps

BASE = (CASES / "hydrostatic.toml").read_text()


def write_case(tmp_path, text, name="case.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


CASES_WITH_ERRORS = {
    "unknown key with suggestion": (
        BASE.replace("density = 1000.0", "densty = 1000.0"),
        "unknown key 'fluid.densty' (did you mean 'density'?)"),
    "unknown section": (BASE + "\n[solver]\nx = 1\n", "unknown key 'solver'"),
    "wrong type": (BASE.replace("end = 2.0", 'end = "soon"'), "time.end must be a number"),
    "spacing not positive": (BASE.replace("spacing = 0.01", "spacing = 0.0"),
                             "particles.spacing must be > 0.0, got 0.0"),
    "beta outside (0, 1)": (BASE + "\n[mps]\nsurface_threshold = 1.2\n",
                            "mps.surface_threshold must be < 1.0, got 1.2"),
    "negative density": (BASE.replace("density = 1000.0", "density = -1.0"),
                         "fluid.density must be > 0.0, got -1.0"),
    "negative viscosity": (BASE.replace("viscosity = 1.0e-6", "viscosity = -1.0e-6"),
                           "fluid.viscosity must be >= 0.0, got -1e-06"),
    "end time not positive": (BASE.replace("end = 2.0", "end = 0.0"),
                              "time.end must be > 0.0, got 0.0"),
    "vector of wrong length": (BASE.replace("lower = [0.0, 0.0]\nupper = [0.2, 0.2]",
                                            "lower = [0.0, 0.0, 0.0]\nupper = [0.2, 0.2]"),
                               "fluid_block[0].lower has 3 components but the case is 2D "
                               "(domain.lower has 2): give [x, y]"),
    "fluid overlapping walls": (BASE.replace("lower = [0.0, 0.0]\nupper = [0.2, 0.2]",
                                             "lower = [-0.02, 0.0]\nupper = [0.2, 0.2]"),
                                "fluid_block[0] overlaps tank[0]"),
    "particles outside the domain": (BASE.replace("upper = [0.26, 0.36]", "upper = [0.1, 0.36]"),
                                     "puts"),
    "not a lattice multiple": (BASE.replace("upper = [0.2, 0.2]", "upper = [0.205, 0.2]"),
                               "fluid_block[0] width: extent 0.205 is not a whole number"),
    "missing section": (BASE.replace("[time]", "[timing]"), "unknown key 'timing'"),
    "syntax error": (BASE + "\n[fluid\n", "not valid TOML"),
    "missing required key": (BASE.replace("end = 2.0\n", ""), "missing key 'time.end'"),
    "missing spacing with fluid": (BASE.replace("[particles]\nspacing = 0.01\n", ""),
                                   "missing key 'particles.spacing': the case has "
                                   "[[fluid_block]] particles"),
}

# Walls with prescribed motion (parmps.boundaries.walls): the tank of BASE, or a box above its water.
MOVING_TANK = "dummy_layers = 2\n"
BOX = "\n[[wall_box]]\nlower = [0.05, 0.22]\nupper = [0.15, 0.28]\n"


def _tank_with(keys):
    return BASE.replace(MOVING_TANK, MOVING_TANK + keys + "\n")


CASES_WITH_ERRORS.update({
    "wall velocity not an array": (_tank_with('velocity = "fast"'),
                                   "tank[0].velocity must be an array, got string"),
    "wall velocity of 3 components": (_tank_with("velocity = [0.0, 0.1, 0.0]"),
                                      "tank[0].velocity has 3 components but the case is 2D"),
    "box velocity component not a number": (BASE + BOX + 'velocity = [0.1, "up"]\n',
                                            "wall_box[0].velocity[1] must be a number"),
    "negative move_start": (_tank_with("move_start = -0.1"),
                            "tank[0].move_start must be >= 0.0, got -0.1"),
    "move_start not a number": (BASE + BOX + 'move_start = "now"\n',
                                "wall_box[0].move_start must be a number, got string"),
    "move_end not positive": (BASE + BOX + "move_end = 0.0\n",
                              "wall_box[0].move_end must be > 0.0, got 0.0"),
    "move_end not after move_start": (BASE + BOX + "move_start = 0.5\nmove_end = 0.5\n",
                                      "wall_box[0].move_end (0.5) must exceed "
                                      "wall_box[0].move_start (0.5)"),
    "misspelt motion key": (_tank_with("move_stop = 1.0"),
                            "unknown key 'tank[0].move_stop' (did you mean 'move_start'?)"),
    "fixed dt too long for a wall": (
        BASE.replace("dt_max = 1.0e-3", "fixed_dt = 6.0e-3") + BOX + "velocity = [0.0, 1.0]\n",
        "wall_box[0].velocity: a wall moving at 1 m/s needs dt <= time.cfl x spacing / speed "
        "= 0.005 s, but time.fixed_dt is 0.006 s"),
    "moving wall leaving the domain": (
        _tank_with("velocity = [0.0, 0.1]"),
        # The tank's top wall particles (y = 0.295) reach the domain's y = 0.36 at 0.65 s.
        "tank[0] moves out of the domain: at tank[0].velocity = [0, 0.1] m/s its particles "
        "leave [-0.06, -0.06]-[0.26, 0.36] at t = 0.65 s, before the end time (2 s)"),
})


@pytest.mark.parametrize("label", sorted(CASES_WITH_ERRORS))
def test_bad_case_exits_2_with_one_line(tmp_path, label):
    text, expected = CASES_WITH_ERRORS[label]
    path = write_case(tmp_path, text)
    result = run_parmps([path, "-o", tmp_path / "out"], timeout=60)
    assert result.returncode == 2, result.stderr
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert len(lines) == 1, result.stderr
    assert lines[0].startswith("parmps: error:")
    assert expected in lines[0], lines[0]
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "out" / "result.h5").exists()


def test_particles_outside_domain_names_the_geometry(tmp_path):
    path = write_case(tmp_path, CASES_WITH_ERRORS["particles outside the domain"][0])
    result = run_parmps([path], timeout=60)
    assert result.returncode == 2
    (line,) = error_lines(result.stderr)
    assert "fluid_block[0] puts" in line and "outside the domain [-0.06, -0.06]-[0.1, 0.36]" in line


@pytest.mark.parametrize("args, expected", [
    (["--set", "fluid.viscosity=-2"], "fluid.viscosity must be >= 0.0"),
    (["--set", "fluid.visc=1"], "unknown key 'fluid.visc'"),
    (["--set", "nonsense"], "expected SECTION.KEY=VALUE"),
    (["--end-time", "-1"], "time.end must be > 0.0"),
    (["--bogus"], "command line: unrecognized arguments: --bogus"),
])
def test_bad_overrides(tmp_path, args, expected):
    result = run_parmps([CASES / "hydrostatic.toml", "--check"] + args, timeout=60)
    assert result.returncode == 2, result.stderr
    (line,) = error_lines(result.stderr)
    assert expected in line


def test_missing_case_file(tmp_path):
    result = run_parmps([tmp_path / "nope.toml"], timeout=60)
    assert result.returncode == 2
    (line,) = error_lines(result.stderr)
    assert "not found" in line


@pytest.mark.mpi
@pytest.mark.parametrize("ranks", [2, 3])
def test_bad_case_under_mpirun_stops_every_rank(tmp_path, ranks):
    text, expected = CASES_WITH_ERRORS["negative density"]
    path = write_case(tmp_path, text)
    result = run_parmps([path, "-o", tmp_path / "out"], ranks=ranks, timeout=60)
    assert result.returncode == 2, result.stderr
    lines = error_lines(result.stderr)
    assert len(lines) == 1, result.stderr
    assert expected in lines[0]
    assert "Traceback" not in result.stderr
