"""The pressure Poisson equation on a distributed PETSc AIJ matrix (docs/design.md).

Rows are the owned unknowns, numbered contiguously per rank (offsets from an
exclusive scan); ghost unknowns carry their global row number. The matrix is
built whole-rows-at-once from CSR arrays.

Options. The KSP has the fixed prefix ``pressure_``. Its options come from the
code's defaults, the case's ``[pressure]`` table and the command line
(``-pressure_ksp_rtol 1e-10``), in that order of precedence. They are not left
in PETSc's global options database: they are inserted for each set-up and
solve of this KSP and removed after, so nothing else sees them and a second
solver could not inherit them. After the first solve every inserted option is
asked whether PETSc used it; one it did not (a misspelt name, an option of
another preconditioner) is reported by name as a warning on rank 0. Options
without the prefix (``-log_view``) go to PETSc itself at start-up.
"""

import contextlib
import ctypes
import functools
import glob
import logging
import math
import os
import sys

import numba
import numpy as np

from parmps.core.lattice import coupling_shells
from parmps.errors import CaseError, RunFailure
from parmps.fluid.relaid import RelaidPreconditioner
from parmps.petsc_options import value_follows

log = logging.getLogger(__name__)

# The second try of a failed solve (PressureSolver._solve_with_diagonal) may take this many
# times the failed solve's iteration limit: CG with the diagonal alone needs some ten times
# GAMG's iterations (84-120 against 4-11 on the 2D dam break at 6.0k particles, 50 steps).
DIAGONAL_ITERATIONS = 10

OPTIONS_PREFIX = "pressure_"
# The solvers that take options from the command line, by their prefix: the pressure's and
# the implicit viscosity's (parmps.fluid.viscous).
SOLVER_PREFIXES = ("pressure_", "viscous_")


def _petsc():
    # Imported here so solid-only cases never load PETSc.
    petsc4py = import_petsc4py()
    if not petsc4py.__dict__.get("_parmps_initialised"):
        petsc4py.init([])
    from petsc4py import PETSc
    apply_malloc_environment()
    return PETSc


# glibc's malloc parameters (malloc.h) by the environment variables that set them.
MALLOPT_PARAMETERS = {"MALLOC_TRIM_THRESHOLD_": -1, "MALLOC_MMAP_THRESHOLD_": -3,
                      "MALLOC_MMAP_MAX_": -4}


def apply_malloc_environment():
    """Apply glibc's malloc settings the environment gives (``MALLOC_MMAP_THRESHOLD_``,
    ``MALLOC_TRIM_THRESHOLD_``, ``MALLOC_MMAP_MAX_``) again, now that PETSc's libraries
    are loaded; glibc only, and nothing when none is set.

    Debian's PETSc links SuperLU_DIST, whose CombBLAS sets, when the library loads, glibc's
    count of mapped blocks to 0 and its trim threshold to never, over what the environment
    said: from PETSc's import on every block comes from the heap, and nothing freed goes
    back to the system. That is the faster choice for the step (its arrays reuse resident
    pages instead of faulting fresh ones), and the code leaves it. It costs memory: the
    heap keeps the holes the step's changing sizes leave. ``MALLOC_MMAP_THRESHOLD_=33554432``
    (blocks of 32 MiB and more mapped, and returned when freed) took the 3D tank's peak at
    5M particles on 2 ranks from 3.1 to 2.64 kB a particle, and its step 12-25 % longer;
    4-9 % with ``GLIBC_TUNABLES=glibc.malloc.hugetlb=1`` (huge pages for the mapped blocks)
    beside it (docs/performance.md, "The heap that never shrinks")."""
    given = {name: os.environ.get(name, "").strip() for name in MALLOPT_PARAMETERS}
    given = {name: int(value) for name, value in given.items() if value.isdigit()}
    if not given:
        return
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    if "MALLOC_MMAP_THRESHOLD_" in given and "MALLOC_MMAP_MAX_" not in given:
        given["MALLOC_MMAP_MAX_"] = 65536  # glibc's default count: a threshold needs one
    for name, value in given.items():
        mallopt(MALLOPT_PARAMETERS[name], value)


# Where Debian's python3-petsc4py lives; its .pth file finds it only when PETSC_DIR is set
# (or petsc-dev is installed), which an activated venv does not do by itself.
DEBIAN_PETSC_DIRS = "/usr/lib/petscdir/petsc*/*-real"


def import_petsc4py():
    """petsc4py, found without PETSC_DIR where Debian's PETSc is installed."""
    try:
        import petsc4py
        return petsc4py
    except ModuleNotFoundError:
        pass
    candidates = sorted(glob.glob(DEBIAN_PETSC_DIRS))
    petsc_dir = os.environ.get("PETSC_DIR") or (candidates[-1] if candidates else None)
    if petsc_dir is None:
        raise CaseError("petsc4py is not installed: run scripts/setup (Debian's "
                        "python3-petsc4py) or set PETSC_DIR to a PETSc with petsc4py")
    os.environ.setdefault("PETSC_DIR", petsc_dir)
    sys.path.append(os.path.join(petsc_dir, "lib", "python3", "dist-packages"))
    try:
        import petsc4py
    except ModuleNotFoundError:
        raise CaseError(f"petsc4py is not installed under PETSC_DIR={petsc_dir}: run "
                        f"scripts/setup (Debian's python3-petsc4py)") from None
    return petsc4py


def initialise(command_line_options):
    """Start PETSc with the command-line options that are not a solver's (``-log_view``);
    returns the solvers', solver (``"pressure"``, ``"viscous"``) -> name (without the
    prefix) -> value."""
    petsc4py = import_petsc4py()
    solvers, others = split_solver_options(command_line_options)
    petsc4py.init(["parmps"] + others)
    petsc4py._parmps_initialised = True
    return solvers


def split_solver_options(tokens):
    """PETSc command-line tokens as (each solver's options, solver -> name without the
    prefix -> value, for the prefixes of SOLVER_PREFIXES; every other token). A value
    follows its name unless it names an option itself
    (:func:`parmps.petsc_options.value_follows`)."""
    solvers, others = {prefix[:-1]: {} for prefix in SOLVER_PREFIXES}, []
    k = 0
    while k < len(tokens):
        name = tokens[k]
        value = None
        if value_follows(tokens, k):
            value = tokens[k + 1]
            k += 1
        k += 1
        prefix = next((p for p in SOLVER_PREFIXES if name.startswith("-" + p)), None)
        if prefix is not None:
            solvers[prefix[:-1]][name[1 + len(prefix):]] = value
        else:
            others += [name] if value is None else [name, value]
    return solvers, others


def gamg_threshold(dimension, re_laplacian):
    """GAMG's threshold for dropping weak couplings when it aggregates, for the Laplacian of
    radius ``re_laplacian`` (in l0) in ``dimension``: the couplings of the lattice's two
    nearest shells (r = l0 and sqrt(2) l0) are kept, the third's and beyond dropped; the
    geometric mean of the second and third shells' relative weights, to one significant
    digit (0.04 in 2D and 0.02 in 3D at re = 3.1 l0).

    Measured on the dam breaks (``bench``, 1 rank, 60 steps): in 2D at 40k particles 0.04
    halves the CG iterations against none dropped and makes set-ups cheaper (0.02 and 0.01:
    3 % slower steps). In 3D a coupling weighs less, a particle having 122 lattice
    neighbours within 3.1 l0 against 28: 0.04 dropped even the nearest (0.039), and the
    SPHERIC tank at 100k particles took 24 iterations a step, 57.5 s; 0.02 took 6.8 and
    40.0 s (0.01: 8.2 iterations, 40.5 s; 0.03: 6.4 and 47.2 s, dearer set-ups).
    """
    _, relative = coupling_shells(re_laplacian, dimension)
    value = math.sqrt(relative[1] * relative[2])
    return float(f"{value:.0e}")


def code_defaults(pc_type, dimension=2, re_laplacian=3.1):
    """The code's PETSc options for a preconditioner: for GAMG the coupling threshold
    (:func:`gamg_threshold`) and one Chebyshev sweep per level instead of two, which costs
    ~2.5 more CG iterations but ~11 % less solve time (paired runs of scripts/bench.py, 2D;
    in 3D two sweeps took 19.3 s of solve against 15.7 s)."""
    if pc_type != "gamg":
        return {}
    return {"pc_gamg_threshold": f"{gamg_threshold(dimension, re_laplacian):g}",
            "mg_levels_ksp_max_it": "1"}


def option_values(settings, on_command_line, dimension=2, re_laplacian=3.1):
    """The PETSc options (names without the prefix) to put in the options database.

    Precedence, lowest first: the code's defaults for the chosen preconditioner
    (:func:`code_defaults`, for the Laplacian's dimension and radius), the case's
    ``[pressure] options`` (names with or without a leading dash), the command line
    (``on_command_line(name)`` says whether it set a name; those are left alone), then
    ``setFromOptions``.
    """
    case_options = {name.lstrip("-"): (str(value).lower() if isinstance(value, bool) else value)
                    for name, value in settings["options"].items()}
    merged = dict(code_defaults(settings["pc_type"], dimension, re_laplacian), **case_options)
    return {name: value for name, value in merged.items() if not on_command_line(name)}


def _type_names(kind):
    return {value for name, value in vars(kind).items() if not name.startswith("_")}


class PressureSolver:
    """One KSP (CG + GAMG by default) reused for every step's pressure system; with another
    ``prefix`` and ``name`` the same machinery for another symmetric system of the particles
    (the implicit viscosity's, :mod:`parmps.fluid.viscous`)."""

    def __init__(self, comm, settings, command_line=None, dimension=2, re_laplacian=3.1,
                 prefix=OPTIONS_PREFIX, name="pressure"):
        """``command_line``: the solver's options given there, name (no prefix) -> value;
        ``dimension`` and ``re_laplacian`` (in l0): the Laplacian's, for the code's
        defaults; ``prefix``: the KSP's options prefix; ``name``: the solver's, for its
        case section and messages."""
        PETSc = _petsc()
        self.PETSc = PETSc
        self.comm = comm
        self.prefix = prefix
        self.name = name
        command_line = dict(command_line or {})
        self.given = sorted(set(command_line) | {name.lstrip("-") for name in settings["options"]})
        # The code's defaults follow the preconditioner that will really run.
        effective = dict(settings, pc_type=command_line.get(
            "pc_type", settings["options"].get("pc_type", settings["pc_type"])))
        self.options = option_values(effective, lambda name: name in command_line,
                                     dimension, re_laplacian)
        self.options.update(command_line)
        self.settings = settings
        self._check_types(command_line)
        self.solves = 0
        self.used = set()
        self.ksp = self._make_ksp()
        self.sizes = None
        self.reuse_limit = settings["reuse_preconditioner"]
        self.setup_cost = settings["setup_cost"]
        self.preconditioner_age = 0
        self.fresh_iterations = None
        self.iterations_since_setup = 0
        self.last_iterations = 0
        self.setups = 0
        # The matrix the preconditioner was last set up on, held while the preconditioner
        # applies it (not GAMG's, see _let_go), its diagonal, and the layout of its rows:
        # their ids in row order on this rank and its first row.
        self.setup_matrix = None
        self.setup_diagonal = None
        self.setup_ids = None
        self.setup_first = 0
        # Where GAMG's finest level points between solves (a matrix of no entries).
        self.placeholder = None
        # The ids of the rows the last solve had, and, while they are not the set-up's,
        # the preconditioner that matches them to it and this step's KSP around it.
        self.layout_ids = None
        self.relaid = None
        self.relaid_ksp = None

    def _check_types(self, command_line):
        """Refuse a KSP or PC type PETSc does not have, naming where it was given."""
        PETSc = self.PETSc
        for kind, known in (("ksp_type", _type_names(PETSc.KSP.Type)),
                            ("pc_type", _type_names(PETSc.PC.Type))):
            if kind in command_line:
                value, where = command_line[kind], f"-{self.prefix}{kind}"
            elif kind in self.options:
                value, where = self.options[kind], f"{self.name}.options.{kind}"
            else:
                value, where = self.settings[kind], f"{self.name}.{kind}"
            if value not in known:
                raise CaseError(f"{where} = {value!r}: PETSc has no such type (e.g. "
                                f"{', '.join(sorted(known)[:8])}, ...)")

    @contextlib.contextmanager
    def _options_inserted(self, report_unused=False):
        """The solver's options in PETSc's database for the block, removed after; with
        ``report_unused``, those PETSc did not use in the block are reported."""
        database = self.PETSc.Options()
        names = [self.prefix + name for name in self.options]
        for name, value in zip(names, self.options.values()):
            database.setValue(name, value)
        try:
            yield
            self._note_used(names)
            if report_unused:
                self._report_unused(names)
        finally:
            for name in names:
                database.delValue(name)

    def _note_used(self, names):
        """Remember which options PETSc has read (its flag goes with the option's removal)."""
        flag = ctypes.c_int(0)
        library = _library(self.PETSc)
        for name in names:
            library.PetscOptionsUsed(None, name.encode(), ctypes.byref(flag))
            if flag.value:
                self.used.add(name)

    def _report_unused(self, names):
        unused = ["-" + name for name in names if name not in self.used]
        if unused and self.comm.rank == 0:
            log.warning("PETSc option%s %s not used by the %s solver (%s): misspelt, or "
                        "meant for another solver type", "s" if len(unused) > 1 else "",
                        ", ".join(unused) + (" were" if len(unused) > 1 else " was"),
                        self.name, self.describe())

    def _make_ksp(self):
        PETSc = self.PETSc
        settings = self.settings
        ksp = PETSc.KSP().create(comm=self.comm)
        ksp.setOptionsPrefix(self.prefix)
        ksp.setType(settings["ksp_type"])
        ksp.getPC().setType(settings["pc_type"])
        ksp.setTolerances(rtol=settings["rtol"], atol=1e-50, max_it=settings["max_iterations"])
        ksp.setInitialGuessNonzero(True)
        # PETSc's own handler would print its error stack; the error is reported as
        # one line instead.
        PETSc.Sys.pushErrorHandler("ignore")
        try:
            with self._options_inserted():
                ksp.setFromOptions()
        except PETSc.Error as error:
            named = ", ".join("-" + self.prefix + name for name in self.given or self.options)
            raise CaseError(f"the {self.name} solver's PETSc options were refused (PETSc error "
                            f"{error.ierr}): check {named}") from None
        finally:
            PETSc.Sys.popErrorHandler()
        return ksp

    @property
    def index_dtype(self):
        """PETSc's integer type: the matrix takes columns of this type without a copy."""
        return np.dtype(self.PETSc.IntType)

    def describe(self):
        return (f"KSP {self.ksp.getType()} + PC {self.ksp.getPC().getType()}, "
                f"rtol {self.ksp.getTolerances()[0]:g}")

    def setup_due(self):
        """Whether the next solve sets its preconditioner up afresh; the same on every rank
        (the rule reads iteration counts, not timings)."""
        return self.fresh_iterations is None or not keep_preconditioner(
            self.preconditioner_age, self.iterations_since_setup, self.last_iterations,
            self.setup_cost, self.reuse_limit)

    def solve(self, owned, other, rhs, guess, step, ids, extra=None):
        """Solve A p = rhs for this rank's rows; returns (p, iterations, residual norm).

        ``owned``, ``other``: the rows' two CSR blocks, each (row pointers, columns,
        values): the columns of this rank's rows numbered from its first, and the other
        ranks' columns, global (:func:`pressure_matrix`; the ranks' rows are numbered
        rank after rank). ``ids``: each row's identity (its particle's id), by which a
        preconditioner kept from an earlier layout of the rows finds them.
        ``rhs`` and ``guess`` of shape (rows, k): k systems of the one matrix (the velocity
        components of the implicit viscosity), solved one after the other; p is then
        (rows, k), the iterations their sum and the residual the largest. ``extra``: None,
        or a symmetric PETSc matrix of the same rows added to A (the implicit viscosity's
        no-slip walls).
        """
        PETSc = self.PETSc
        matrix, csr = pressure_matrix(PETSc, self.comm, owned, other)
        if extra is not None:
            matrix.axpy(1.0, extra, structure=PETSc.Mat.Structure.DIFFERENT_NONZERO_PATTERN)
            matrix.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        b = matrix.createVecLeft()
        x = matrix.createVecRight()
        ids = np.asarray(ids)
        rhs, guess = np.asarray(rhs), np.asarray(guess)
        # The same number of systems on every rank (the solves are collective), rows or not.
        columns = rhs[:, None] if rhs.ndim == 1 else rhs
        guesses = guess.reshape(columns.shape)
        solution = np.empty(columns.shape)
        iterations, residual, reused, failure = 0, 0.0, True, None
        for k in range(columns.shape[1]):
            b.getArray()[:] = columns[:, k]
            its, norm, reuse, failure = self._solve_system(matrix, b, x, guesses[:, k], step,
                                                           ids)
            solution[:, k] = x.getArray()
            iterations, residual, reused = iterations + its, max(residual, norm), reused and reuse
            if failure is not None:
                break
        self._let_go(matrix, reused)
        for item in (b, x):
            item.destroy()
        del csr
        if failure is not None:
            failed, reason, its = failure
            raise RunFailure(f"{self.name} solve diverged at step {step}: "
                             f"{_reason_name(PETSc, failed[0])} after {failed[1]} iterations "
                             f"(residual {failed[2]:.3e}), with a preconditioner set up for "
                             f"this step's matrix, and {_reason_name(PETSc, reason)} after "
                             f"{its} iterations with the diagonal alone; the run may have "
                             f"gone unstable (lower time.cfl or time.dt_max), or the solver "
                             f"needs other settings (e.g. -{self.prefix}pc_type hypre, "
                             f"-{self.prefix}ksp_max_it)")
        return solution.reshape(rhs.shape), iterations, residual

    def _solve_system(self, matrix, b, x, guess, step, ids):
        """One right-hand side ``b`` into ``x``; returns (iterations, residual norm, whether
        the preconditioner was reused, None or the failure: ((reason, iterations, residual)
        of the failed solve, the diagonal's reason, its iterations))."""
        reuse = not self.setup_due()
        ksp = self._fit_layout(matrix, ids, reuse)
        reason = self._solve_with(ksp, matrix, b, x, guess, reuse,
                                  report_unused=self.solves == 0)
        self.solves += 1
        if reason < 0 and reuse:
            # A preconditioner kept from earlier matrices can be indefinite for this one
            # (CG then stops with DIVERGED_INDEFINITE_PC): solve again with one set up
            # for this matrix before calling the step a failure. Every rank reuses or
            # not alike, so every rank takes this branch together.
            reuse = False
            ksp = self._fit_layout(matrix, ids, reuse)
            reason = self._solve_with(ksp, matrix, b, x, guess, reuse)
        iterations = ksp.getIterationNumber()
        residual = ksp.getResidualNorm()
        self._count(iterations, reuse)
        if reason >= 0:
            return iterations, residual, reuse, None
        failed = (reason, iterations, residual)
        reason, iterations, residual = self._solve_with_diagonal(
            matrix, b, x, guess, step, failed, ksp.getTolerances())
        # The set-up this matrix defeated is not kept for the next step's.
        self.fresh_iterations = None
        return iterations, residual, reuse, None if reason >= 0 else (failed, reason, iterations)

    def _solve_with_diagonal(self, matrix, b, x, guess, step, failed, tolerances):
        """The step's second try when the solve fails with a preconditioner set up for its
        own matrix: CG with the diagonal (Jacobi) alone, from the same guess, to the failed
        solve's ``tolerances`` (rtol, atol, dtol, max_it: PETSc's, options included) but
        DIAGONAL_ITERATIONS times its iterations. Returns (reason, iterations, residual).

        GAMG's smoothers (Chebyshev over Jacobi) take the upper end of each level's
        spectrum from a short estimate at the set-up. A mode on a few rows alone (a few
        particles packed close after a splash) can reach past it, unseen by the estimate,
        and the smoother then amplifies that mode: the preconditioner is indefinite and CG
        stops (DIVERGED_INDEFINITE_PC), however small the step. Measured on the SPHERIC
        tank at 0.55/15 m, 1 rank, step 3842: the Jacobi-scaled spectrum reaches 1.483, on
        three particles, the finest level's bound was 1.349. The pressure matrix itself is
        symmetric positive definite (an M-matrix; there its eigenvalues run from 19 to 3903),
        so CG with the diagonal alone converges on it; it is slower, and runs only here."""
        PETSc = self.PETSc
        ksp = PETSc.KSP().create(comm=self.comm)
        try:
            ksp.setOptionsPrefix(self.prefix + "diagonal_")
            ksp.setType(PETSc.KSP.Type.CG)
            ksp.getPC().setType(PETSc.PC.Type.JACOBI)
            rtol, atol, dtol, max_it = tolerances
            ksp.setTolerances(rtol=rtol, atol=atol, divtol=dtol,
                              max_it=DIAGONAL_ITERATIONS * max_it)
            ksp.setInitialGuessNonzero(True)
            ksp.setOperators(matrix)
            x.getArray()[:] = guess
            ksp.solve(b, x)
            reason = ksp.getConvergedReason()
            iterations, residual = ksp.getIterationNumber(), ksp.getResidualNorm()
        finally:
            ksp.destroy()
        if reason >= 0 and self.comm.rank == 0:
            log.warning("step %d: the %s solve stopped with %s after %d iterations, its "
                        "preconditioner set up for this step's matrix; solved with the "
                        "diagonal alone in %d iterations, and the next step sets its "
                        "preconditioner up afresh", step, self.name,
                        _reason_name(PETSc, failed[0]),
                        failed[1], iterations)
        return reason, iterations, residual

    def _let_go(self, matrix, reuse):
        """After a solve, let this step's matrix go, and the set-up's where nothing applies it.

        GAMG applies a matrix only on its finest level (the smoother and the residual); its
        coarser levels, made by the set-up, are their own. So once set up it needs no
        matrix between solves: its finest level, and the KSP, are pointed at a matrix of no
        entries (:meth:`_park`) and each solve points them at its own matrix, that of the
        set-up's layout or, on a later layout, the step's seen through the rows' ids
        (:class:`parmps.fluid.relaid.RelaidPreconditioner`). At no time are two systems'
        matrices alive: the step's is assembled and its preconditioner set up or applied
        with no other beside it (3D at 2.3 l0: 12 bytes an entry, some 40 entries a row;
        the peak at 972k particles on 2 ranks, 3.0 kB a particle with the set-up's matrix
        held, 2.5 kB without). The smoother's Jacobi diagonal is the step's, its Chebyshev
        bounds the set-up's.

        Other preconditioners may apply the set-up's matrix itself (SOR does): the KSP holds
        that one, and lets each step's go."""
        self._drop_relaid_ksp()
        if self.relaid is not None:
            self.relaid.use(None)
        parks = self._parks()
        if not reuse:
            self._release_setup_matrix()
            self._keep_setup_diagonal(matrix)
            if parks:
                unpin_finest_matrix(self.PETSc, self.ksp.getPC())
                self._make_placeholder()
            else:
                self.setup_matrix = matrix
                return
        if parks:
            self._park()
        else:
            self.ksp.setOperators(self.setup_matrix)
        matrix.destroy()

    def _parks(self):
        """Whether the preconditioner needs no matrix between solves: GAMG with more than
        one level (a single level is a direct solve of the set-up's matrix)."""
        pc = self.ksp.getPC()
        return pc.getType() == self.PETSc.PC.Type.GAMG and pc.getMGLevels() > 1

    def _keep_setup_diagonal(self, matrix):
        # The set-up's diagonal: a row of the set-up the later layout has lost keeps it.
        if self.setup_diagonal is not None:
            self.setup_diagonal.destroy()
        self.setup_diagonal = matrix.getDiagonal()

    def _make_placeholder(self):
        """A matrix of the set-up's sizes with no entries; made at each set-up, which every
        rank does together (making it is collective)."""
        if self.placeholder is not None:
            self.placeholder.destroy()
        sizes = (self.setup_diagonal.getSizes(),) * 2
        self.placeholder = self.PETSc.Mat().create(comm=self.comm)
        self.placeholder.setSizes(sizes)
        self.placeholder.setType(self.PETSc.Mat.Type.SHELL)
        self.placeholder.setUp()

    def _park(self):
        """Point the KSP and GAMG's finest level at the placeholder, so that nothing PETSc
        holds keeps a system's matrix alive."""
        self.ksp.setOperators(self.placeholder)
        point_finest_level(self.PETSc, self.ksp.getPC(), self.placeholder)

    def _release_setup_matrix(self):
        if self.setup_matrix is not None:
            self.setup_matrix.destroy()
            self.setup_matrix = None

    def _fit_layout(self, matrix, ids, reuse):
        """The KSP for this solve; collective (every rank decides alike, or PETSc hangs).

        Set up afresh (``reuse`` false): the KSP of the set-ups, made anew when the rows'
        sizes changed (a preconditioner cannot change size), and the rows' ids kept as the
        set-up's layout. Reused, on the layout of the set-up: that KSP. Reused on a layout
        the rows have changed to since (migration, or a rank's rows numbered afresh): a KSP
        of its own whose preconditioner is the set-up's, applied through the rows' ids
        (:class:`parmps.fluid.relaid.RelaidPreconditioner`): the set-up the new layout
        would otherwise force is left to the policy."""
        moved = not np.array_equal(ids, self.layout_ids) if self.layout_ids is not None else True
        if self.comm.allreduce(int(moved)) > 0:
            self._drop_relaid()
            self.layout_ids = ids.copy()
            if reuse:
                self.relaid = RelaidPreconditioner(
                    self.PETSc, self.comm, self.ksp.getPC(), self.setup_diagonal,
                    self.setup_ids, self.setup_first, ids, matrix,
                    finest_level=self._parks())
        if reuse:
            if self.relaid is None:
                return self.ksp
            self.relaid.use(matrix)
            if self.relaid.operator is not None:
                point_finest_level(self.PETSc, self.ksp.getPC(), self.relaid.operator)
            self.relaid_ksp = self._make_ksp()
            pc = self.relaid_ksp.getPC()
            pc.setType(self.PETSc.PC.Type.PYTHON)
            pc.setPythonContext(self.relaid)
            return self.relaid_ksp
        self._drop_relaid()
        # The set-up replaces the hierarchy built on the last set-up's matrix: let that
        # matrix go now, not after the solve, or it is held beside the new one and the
        # set-up's own work, the step's largest allocation (3D: 12 bytes an entry, some
        # 50 entries a row).
        self._release_setup_matrix()
        if self.comm.allreduce(int(matrix.getSizes() != self.sizes)) > 0:
            self.ksp.destroy()
            self.ksp = self._make_ksp()
            self.sizes = matrix.getSizes()
        self.layout_ids = ids.copy()
        self.setup_ids = self.layout_ids
        self.setup_first = matrix.getOwnershipRange()[0]
        return self.ksp

    def _drop_relaid_ksp(self):
        if self.relaid_ksp is not None:
            self.relaid_ksp.destroy()
            self.relaid_ksp = None

    def _drop_relaid(self):
        self._drop_relaid_ksp()
        if self.relaid is not None:
            self.relaid.release()
            self.relaid = None

    def _solve_with(self, ksp, matrix, b, x, guess, reuse, report_unused=False):
        """One KSP solve from ``guess``, the preconditioner kept or set up afresh; returns
        PETSc's converged reason. The first solve sets the preconditioner up, which reads
        the rest of the options."""
        ksp.getPC().setReusePreconditioner(reuse)
        ksp.setOperators(matrix)
        if ksp is self.ksp and self._parks():
            # The kept hierarchy's finest level applies this step's matrix; before a
            # set-up, the set-up takes the KSP's for it.
            point_finest_level(self.PETSc, ksp.getPC(), matrix)
        x.getArray()[:] = guess
        with self._options_inserted(report_unused=report_unused):
            ksp.solve(b, x)
        return ksp.getConvergedReason()

    def _count(self, iterations, reuse):
        """The reuse policy's tallies after a solve (``keep_preconditioner``)."""
        self.last_iterations = iterations
        if reuse:
            self.preconditioner_age += 1
            self.iterations_since_setup += iterations
        else:
            self.preconditioner_age = 0
            self.iterations_since_setup = iterations
            self.fresh_iterations = iterations
            self.setups += 1

    def destroy(self):
        self._drop_relaid()
        self.ksp.destroy()
        self._release_setup_matrix()
        for item in (self.setup_diagonal, self.placeholder):
            if item is not None:
                item.destroy()


@functools.lru_cache(maxsize=None)
def _library(PETSc):
    """PETSc's C library, for the calls petsc4py does not wrap."""
    return ctypes.CDLL(PETSc.__file__)


def point_finest_level(PETSc, pc, matrix):
    """Make the finest level of a set-up multigrid preconditioner ``pc`` apply ``matrix``:
    its smoother (whose Jacobi diagonal is then ``matrix``'s) and its residual."""
    finest = pc.getMGLevels() - 1
    pc.getMGSmoother(finest).setOperators(matrix)
    residual = _library(PETSc).PCMGSetResidual
    residual.argtypes = (ctypes.c_void_p, ctypes.c_int, ctypes.c_void_p, ctypes.c_void_p)
    _check(PETSc, residual(pc.handle, finest, None, matrix.handle))


def unpin_finest_matrix(PETSc, pc):
    """After GAMG's set-up: the Galerkin product that made the next level keeps the finest
    matrix, to redo the product with it; a later set-up makes its own, so let it go."""
    levels = pc.getMGLevels()
    coarse = pc.getMGSmoother(levels - 2).getOperators()[0]
    clear = _library(PETSc).MatProductClear
    clear.argtypes = (ctypes.c_void_p,)
    _check(PETSc, clear(coarse.handle))


def _check(PETSc, error):
    """Raise PETSc's error for a C call's nonzero return, as petsc4py does."""
    if error:
        raise PETSc.Error(error)


def pressure_matrix(PETSc, comm, owned, other):
    """This rank's rows, in two CSR blocks (row pointers, columns, values), as an assembled
    PETSc matrix marked symmetric; returns (matrix, the CSR arrays it is made on).

    ``owned``: the columns of the rank's own rows, numbered from its first row; ``other``:
    the other ranks' columns, global (no entries on one rank). Each row's entries are
    sorted by column in the blocks' own arrays when their types are PETSc's (the caller's
    arrays change order).

    Made on the CSR arrays themselves (sorted rows), not row by row: a tenth of the cost.
    PETSc keeps the arrays without copying them, on one rank as the matrix and on several
    as its two blocks (``MatCreateMPIAIJWithSplitArrays``; petsc4py keeps them with the
    matrix, alive as long as it is).

    Every Laplacian's rows are symmetric by construction (a pair's weight depends on its
    distance alone, and a row left out or held at P = 0 takes its column with it; checked
    at every step by tests/mpi/symmetric_pressure_matrix.py). Saying so lets GAMG build its
    graph from the matrix as it is, without the transpose and the sum it otherwise forms to
    symmetrise it: a third of a set-up in 2D, a fifth in 3D. The flag is set after the
    assembly, which clears it.
    """

    def petsc_types(block):
        # Taken as they are where their types are PETSc's (the values: float64), and
        # sorted in place: a copy of the values cost 9-17 ms a step at 4.6M entries (3D,
        # 100k particles), mostly the first touch of its fresh pages.
        row_ptr, columns, values = block
        block = (row_ptr.astype(PETSc.IntType, copy=False),
                 columns.astype(PETSc.IntType, copy=False),
                 values.astype(PETSc.ScalarType, copy=False))
        sort_row_columns(*block)
        return block

    n_local = len(owned[0]) - 1
    if comm.size > 1:
        csr = (petsc_types(owned), petsc_types(other))
    elif len(other[1]):
        raise ValueError("pressure_matrix: columns of other ranks on one rank")
    else:
        csr = petsc_types(owned)
    matrix = PETSc.Mat().createAIJWithArrays(
        size=((n_local, PETSc.DETERMINE), (n_local, PETSc.DETERMINE)), csr=csr, comm=comm)
    # PETSc returns it assembled; assembled again all the same: without this the matrix's
    # making and the solves measured slower (3D, 289k, 2 ranks; docs/performance.md).
    matrix.assemble()
    matrix.setOption(PETSc.Mat.Option.SYMMETRIC, True)
    matrix.setOption(PETSc.Mat.Option.STRUCTURALLY_SYMMETRIC, True)
    return matrix, csr


def keep_preconditioner(reuses, iterations_since_setup, last_iterations, setup_cost, limit):
    """Whether the next solve should reuse the preconditioner set up ``reuses`` solves ago.

    The AMG hierarchy of a recent matrix preconditions this one well while the
    particles move little, and less well as they move on. A set-up is paid for by
    the solves that reuse it, so it is renewed once the last solve took more
    iterations than the average cost per solve since the set-up (the set-up
    counted as ``setup_cost`` iterations; ``iterations_since_setup`` includes the
    set-up's own solve): from then on that average could only grow. At most
    ``limit`` reuses. Iteration counts, not timings, so every run decides alike.
    """
    average = (setup_cost + iterations_since_setup) / (reuses + 1)
    return reuses < limit and last_iterations <= average


def _reason_name(PETSc, reason):
    for name in dir(PETSc.KSP.ConvergedReason):
        if not name.startswith("_") and getattr(PETSc.KSP.ConvergedReason, name) == reason:
            return f"{name} ({reason})"
    return f"KSP reason {reason}"


# Ciura's gaps for Shell sort, largest first, for rows of at least _SHELL_FROM entries
# (measured: 2D rows of ~30 took 9 ms a step at 40k particles by Shell sort, 4.9 by insertion;
# 3D rows of ~90, 88 ms a step at 100k particles against 125).
_SHELL_GAPS = np.array([701, 301, 132, 57, 23, 10, 4, 1], np.int64)
_SHELL_FROM = 64

# A row with at most one descent per this many entries is sorted by insertion alone.
_NEARLY_SORTED = 8


@numba.njit(cache=True, inline="always")
def _descents(columns, start, end):
    """How many entries of the row [start, end) are smaller than the one before."""
    count = 0
    for p in range(start + 1, end):
        if columns[p] < columns[p - 1]:
            count += 1
    return count


@numba.njit(cache=True)
def sort_row_columns(row_ptr, columns, values):
    """Sort each CSR row's entries by column, in place: insertion sort, preceded for long rows
    by Shell sort's larger gaps (Ciura's).

    PETSc's matrix made directly on CSR arrays (``MatCreateSeqAIJWithArrays``) takes
    the arrays as they are and requires sorted rows; building the matrix row by row
    instead cost 10x more (14 ms against 1.1 ms for 6.8k rows). The neighbour lists come
    cell by cell, so a row is far from sorted in 3D (~120 entries): plain insertion took
    half the 3D solve's time on one rank (125 ms a step at 5.8M entries).

    A row already ascending (the pressure rows numbered in the search's cell order) is
    only read; a nearly ascending one (the same numbering kept while particles move) is
    sorted by insertion alone, in about one pass.
    """
    for row in range(row_ptr.shape[0] - 1):
        start = row_ptr[row]
        length = row_ptr[row + 1] - start
        descents = _descents(columns, start, start + length)
        if descents == 0:
            continue
        nearly_sorted = descents * _NEARLY_SORTED <= length
        for gap in _SHELL_GAPS:
            # Short rows (2D, ~30 entries) are sorted faster by insertion alone.
            if gap >= length or (gap > 1 and (length < _SHELL_FROM or nearly_sorted)):
                continue
            for p in range(start + gap, start + length):
                column = columns[p]
                value = values[p]
                q = p - gap
                while q >= start and columns[q] > column:
                    columns[q + gap] = columns[q]
                    values[q + gap] = values[q]
                    q -= gap
                columns[q + gap] = column
                values[q + gap] = value

