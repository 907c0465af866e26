"""The structure of the package: no import cycles, registries that load, the dimension,
scoped PETSc options and the pressure gradient the coupling takes from the fluid."""

import ast
import importlib
import os
import pkgutil
import sys
from pathlib import Path

import numpy as np
import pytest

import parmps
from conftest import CASES, error_lines, run_parmps
from parmps import config, schema
from parmps.core import operators
from parmps.core.neighbours import pair_list
from parmps.core.particles import DUMMY, FLUID, SOLID, WALL, Particles
from parmps.errors import CaseError
from parmps.fluid.constants import MPSConstants
from parmps.fluid.schemes import (GRADIENTS, LAPLACIANS, SHIFTINGS, SOURCES, SURFACES,
                                  registered,
                                  scheme_class)

PACKAGE = Path(parmps.__file__).parent


def _modules():
    return sorted(m.name for m in pkgutil.walk_packages([str(PACKAGE)], "parmps."))


def import_graph():
    """Module -> the parmps modules it imports, at any depth of its code (lazy ones too)."""
    names = set(_modules()) | {"parmps"}
    graph = {}
    for name in names:
        path = PACKAGE.joinpath(*name.split(".")[1:])
        path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
        targets = set()
        package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets |= {alias.name for alias in node.names}
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    base = ".".join(package.split(".")[:len(package.split(".")) - node.level + 1]
                                    + ([node.module] if node.module else []))
                for alias in node.names:
                    full = f"{base}.{alias.name}"
                    targets.add(full if full in names else base)
        graph[name] = {t for t in targets if t in names and t != name}
    return graph


def test_no_import_cycle():
    graph = import_graph()
    # Tarjan's strongly connected components: a cycle is a component of two or more.
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(node):
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in graph[node]:
            if target not in index:
                visit(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            visit(node)
    assert not cycles, f"import cycles: {cycles}"


def test_the_walk_sees_a_cycle():
    # The walk itself must be able to fail: the machinery of a case imports nothing of
    # the package's physics, but the schema imports every component's settings.
    graph = import_graph()
    assert "parmps.config" in graph["parmps.fluid.settings"]
    assert "parmps.fluid.settings" in graph["parmps.schema"]
    assert not any(target.startswith(("parmps.fluid", "parmps.solids", "parmps.run"))
                   for target in graph["parmps.config"])


# The repository's folders beside the package: study code (scripts/) and the validations'
# data and plots (validation/). The package must run without them (an installed parmps has
# neither); its own validation module is parmps.validation.
OUTSIDE_THE_PACKAGE = ("scripts", "validation")


def imports_from_outside(source):
    """The absolute imports in ``source`` (statements, and import_module or __import__ of a
    literal name) whose top-level package is one of OUTSIDE_THE_PACKAGE."""
    found = []
    for node in ast.walk(ast.parse(source)):
        names = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0:
            names = [node.module or ""]
        elif (isinstance(node, ast.Call) and node.args
              and isinstance(node.args[0], ast.Constant) and isinstance(node.args[0].value, str)
              and getattr(node.func, "attr", getattr(node.func, "id", None))
              in ("import_module", "__import__")):
            names = [node.args[0].value]
        found += [name for name in names if name.split(".")[0] in OUTSIDE_THE_PACKAGE]
    return found


def test_no_module_of_the_package_imports_scripts_or_validation():
    offenders = []
    for name in sorted(set(_modules()) | {"parmps"}):
        path = PACKAGE.joinpath(*name.split(".")[1:])
        path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
        offenders += [f"{name}: {target}" for target in imports_from_outside(path.read_text())]
    assert not offenders, offenders
    # The check sees each form (and leaves the package's own validation module alone).
    assert imports_from_outside("import scripts.study\nfrom validation.dam_break import plot\n"
                                "importlib.import_module('scripts.bench')\n"
                                "from parmps.validation import launch\nfrom . import validation\n"
                                ) == ["scripts.study", "validation.dam_break", "scripts.bench"]


def test_the_command_line_and_the_solvers_pair_options_and_values_alike():
    """One tokeniser: a value follows its option's name unless it names an option itself (a
    negative number does not)."""
    from parmps.cli import split_petsc_options
    from parmps.fluid.ppe import split_solver_options
    ours, petsc = split_petsc_options(["case.toml", "-pressure_ksp_rtol", "1e-9", "-log_view",
                                       "--end-time", "0.1", "-viscous_ksp_atol", "-1e-3",
                                       "-pressure_ksp_monitor"])
    assert ours == ["case.toml", "--end-time", "0.1"]
    solvers, others = split_solver_options(petsc)
    assert solvers == {"pressure": {"ksp_rtol": "1e-9", "ksp_monitor": None},
                       "viscous": {"ksp_atol": "-1e-3"}}
    assert others == ["-log_view"]


def test_every_module_imports_without_side_effects():
    for name in _modules():
        if not name.endswith("__main__"):
            importlib.import_module(name)


def test_every_registered_scheme_loads_and_declares_its_settings():
    assert set(SOURCES) >= {"density", "mixed"} and set(GRADIENTS) >= {"minimum", "corrected"}
    assert set(SOURCES) >= {"density_rate", "compensated_rate", "density_acceleration"}
    assert set(LAPLACIANS) >= {"standard", "higher_order"}
    assert set(SURFACES) >= {"dirichlet", "extrapolated"}
    assert set(SHIFTINGS) >= {"none", "fickian", "dynamic_stabilisation"}
    # one [mps.<name>] table each
    names = [*SOURCES, *LAPLACIANS, *GRADIENTS, *SURFACES, *SHIFTINGS]
    assert len(set(names)) == len(names)
    for name, scheme in registered():
        assert isinstance(scheme.KEYS, dict)
        assert (hasattr(scheme, "rhs") or hasattr(scheme, "rows")
                or hasattr(scheme, "gradient") or hasattr(scheme, "unknowns")
                or hasattr(scheme, "regularise")), name
    case = _validated()
    for name in names:
        assert isinstance(case["mps"][name], dict)


def _validated(extra=""):
    return schema.validate(config.load_text((CASES / "hydrostatic.toml").read_text() + extra))


@pytest.mark.parametrize("old, new", [
    ("source_term = \"mixed\"", "mps.source"),
    ("relaxation = 0.3", "[mps.density] relaxation"),
    ("mixed_relaxation = 0.1", "[mps.mixed] relaxation"),
    ("gradient_correction = true", "mps.gradient = \"corrected\""),
    ("gradient_correction_limit = 0.5", "[mps.corrected] eigenvalue_limit"),
])
def test_replaced_scheme_keys_name_their_successors(old, new):
    with pytest.raises(CaseError) as error:
        _validated(f"\n[mps]\n{old}\n")
    assert f"mps.{old.split(' ')[0]} is no longer a key" in str(error.value)
    assert new in str(error.value)


def test_scheme_settings_reach_the_scheme():
    case = _validated("\n[mps]\nsource = \"mixed\"\ngradient = \"corrected\"\n"
                      "[mps.mixed]\nrelaxation = 0.05\n[mps.corrected]\neigenvalue_limit = 0.5\n")
    constants = MPSConstants.from_case(case)
    source = scheme_class(SOURCES, "mixed")(case["mps"]["mixed"], constants)
    gradient = scheme_class(GRADIENTS, "corrected")(case["mps"]["corrected"], constants)
    assert source.relaxation == 0.05 and gradient.eigenvalue_limit == 0.5
    with pytest.raises(CaseError, match="mps.mixed.relaxtion"):
        _validated("\n[mps.mixed]\nrelaxtion = 0.05\n")


def test_a_3d_case_is_refused_with_a_clear_message(tmp_path):
    text = (CASES / "hydrostatic.toml").read_text().replace(
        "[domain]\nlower = [-0.06, -0.06]", "[domain]\nlower = [-0.06, -0.06, 0.0]")
    assert "lower = [-0.06, -0.06, 0.0]" in text
    path = tmp_path / "three_d.toml"
    path.write_text(text)
    result = run_parmps([path, "--check"], timeout=60)
    assert result.returncode == 2
    (line,) = error_lines(result.stderr)
    assert "3D" in line and "domain.lower" in line and "Traceback" not in result.stderr


def test_a_mistyped_pressure_option_is_reported(tmp_path):
    result = run_parmps([CASES / "hydrostatic.toml", "-o", tmp_path, "--end-time", "0.005",
                         "-pressure_ksp_typoo", "3", "-pressure_ksp_rtol", "1e-9"], timeout=120)
    assert result.returncode == 0, result.stderr
    warnings = [line for line in result.stderr.splitlines() if "WARNING" in line]
    assert len(warnings) == 1 and "-pressure_ksp_typoo" in warnings[0], warnings
    assert "-pressure_ksp_rtol" not in warnings[0]  # used: not reported


def test_pressure_options_leave_no_trace_in_petsc():
    from parmps.fluid.ppe import PressureSolver, _petsc
    PETSc = _petsc()
    settings = _validated()["pressure"]
    solver = PressureSolver(__import__("mpi4py.MPI", fromlist=["MPI"]).COMM_WORLD, settings,
                            {"ksp_rtol": "1e-9"})
    try:
        assert not any(name.startswith("pressure_") for name in PETSc.Options().getAll())
        assert solver.ksp.getTolerances()[0] == 1e-9
    finally:
        solver.destroy()


@pytest.mark.parametrize("option, value", [("ksp_type", "nonsense"), ("pc_type", "nonsense")])
def test_an_unknown_solver_type_is_bad_input(tmp_path, option, value):
    result = run_parmps([CASES / "hydrostatic.toml", "-o", tmp_path, "--end-time", "0.005",
                         f"-pressure_{option}", value], timeout=120)
    assert result.returncode == 2
    (line,) = error_lines(result.stderr)
    assert f"-pressure_{option}" in line and value in line
    assert "PETSC ERROR" not in result.stderr and "Traceback" not in result.stderr


def _jittered_scene(spacing, seed=3):
    """A lattice of fluid with a solid node in the middle, jittered, and a linear pressure."""
    rng = np.random.default_rng(seed)
    grid = np.arange(-6, 7) * spacing
    x, y = np.meshgrid(grid, grid)
    position = np.column_stack([x.ravel(), y.ravel()])
    position += rng.uniform(-0.15, 0.15, position.shape) * spacing
    centre = int(np.argmin(np.hypot(*position.T)))
    kind = np.full(len(position), FLUID, np.int8)
    kind[centre] = SOLID
    return position, kind, centre


def test_the_coupling_feels_the_fluids_corrected_gradient():
    """With mps.gradient = "corrected", a body node feels -V times the gradient the fluid
    moves by, on a disordered arrangement where the corrected and the plain MPS gradients
    differ. (Before the schemes were shared, the coupling took the plain gradient.)"""
    from parmps.fluid.forces import fluid_forces
    case = _validated("\n[mps]\ngradient = \"corrected\"\n")
    case["fluid"]["viscosity"] = 0.0
    constants = MPSConstants.from_case(case)
    corrected = scheme_class(GRADIENTS, "corrected")(case["mps"]["corrected"], constants)
    plain = scheme_class(GRADIENTS, "minimum")({}, constants)
    position, kind, centre = _jittered_scene(constants.spacing)
    pressure = 5000.0 + position @ np.array([300.0, -900.0]) + 4e5 * position[:, 0] ** 2
    particles = Particles({"id": np.arange(len(position)), "kind": kind,
                           "position": position, "pressure": pressure})
    force = fluid_forces(particles, np.array([centre]), constants, corrected)[0]
    indptr, cols = pair_list(position, constants.re_laplacian)
    has_pressure = kind != DUMMY
    volume = constants.spacing ** 2
    by_fluid = -volume * corrected.gradient(indptr, cols, position, pressure, has_pressure,
                                            len(position))[centre]
    by_plain = -volume * plain.gradient(indptr, cols, position, pressure, has_pressure,
                                        len(position))[centre]
    np.testing.assert_allclose(force, by_fluid, rtol=1e-12)
    # The two gradients differ here by far more than rounding: the test tells them apart.
    assert np.abs(by_plain - by_fluid).max() > 1e-2 * np.abs(by_fluid).max()


def test_one_blas_thread_per_rank_unless_the_user_chose(monkeypatch):
    from parmps import cli
    from parmps.parallel.mpi import BLAS_THREAD_VARIABLES, one_blas_thread_per_rank
    environ = {"OMP_NUM_THREADS": "3"}
    one_blas_thread_per_rank(environ)
    assert environ == {"OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "3"}
    # main() sets it before anything loads PETSc (and OpenBLAS with it).
    for variable in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(variable, raising=False)
    assert cli.main(["--help"]) == 0
    assert all(os.environ[variable] == "1" for variable in BLAS_THREAD_VARIABLES)


def test_launched_programs_get_one_blas_thread_unless_the_user_chose(monkeypatch):
    """Every program parmps launches by either launcher (the benchmark's worker and the
    tests' MPI programs are not ``python -m parmps``) starts with one BLAS thread per rank,
    and OpenBLAS, when it is numpy's BLAS, runs with it."""
    from parmps.parallel.mpi import BLAS_THREAD_VARIABLES, launch_environment
    from parmps.validation import launch
    for variable in BLAS_THREAD_VARIABLES:
        monkeypatch.delenv(variable, raising=False)
    for env in (launch.environment(), launch_environment()):
        assert all(env[variable] == "1" for variable in BLAS_THREAD_VARIABLES)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "2")
    assert launch.environment()["OPENBLAS_NUM_THREADS"] == "2"
    monkeypatch.delenv("OPENBLAS_NUM_THREADS")
    probe = ("import ctypes, numpy\n"
             "paths = {line.split()[-1] for line in open('/proc/self/maps') if 'libopenblas' in line}\n"
             "print(ctypes.CDLL(paths.pop()).openblas_get_num_threads() if paths else 'none')")
    status, stdout, stderr, _ = launch.execute([sys.executable, "-c", probe], timeout=60)
    assert status == 0, stderr
    assert stdout.strip() in ("1", "none")


def test_nothing_outside_parallel_names_a_decomposition():
    """The solver, the coupling, the boundaries and the output get their decomposition from
    parmps.parallel.create_decomposition: no module outside parmps.parallel imports a
    decomposition's module or class, so a new decomposition needs no change elsewhere."""
    from parmps.parallel import DECOMPOSITIONS
    modules = {target.split(":")[0] for target in DECOMPOSITIONS.values()}
    classes = {target.split(":")[1] for target in DECOMPOSITIONS.values()}
    offenders = []
    for name in _modules():
        if name.startswith("parmps.parallel"):
            continue
        path = PACKAGE.joinpath(*name.split(".")[1:])
        path = path / "__init__.py" if path.is_dir() else path.with_suffix(".py")
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                imported = {f"{node.module}.{alias.name}" for alias in node.names}
                named = {alias.name for alias in node.names}
                if node.module in modules or imported & modules or named & classes:
                    offenders.append(f"{name}: from {node.module} import "
                                     f"{', '.join(sorted(named))}")
            elif isinstance(node, ast.Import):
                offenders += [f"{name}: import {alias.name}" for alias in node.names
                              if alias.name in modules]
            elif isinstance(node, ast.Name) and node.id in classes:
                offenders.append(f"{name}: names {node.id}")
    assert not offenders, offenders
    # The check can fail: the slabs' module is registered and names its class.
    assert "parmps.parallel.slabs" in modules and "SlabDecomposition" in classes
