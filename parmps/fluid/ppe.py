"""The pressure Poisson equation on a distributed PETSc AIJ matrix (DESIGN.md §1.2, §2).

Rows are the owned unknowns, numbered contiguously per rank (offsets from an
exclusive scan); ghost unknowns carry their global row number. The matrix is
built whole-rows-at-once from CSR arrays; the KSP has the options prefix
``pressure_`` so the case file and the command line (``-pressure_ksp_rtol``)
reach it, in that order of precedence over the code's defaults.
"""

import logging

from parmps.errors import RunFailure

log = logging.getLogger(__name__)

OPTIONS_PREFIX = "pressure_"


def _petsc():
    # Imported here so solid-only cases never load PETSc.
    import petsc4py
    if not petsc4py.__dict__.get("_parmps_initialised"):
        petsc4py.init([])
    from petsc4py import PETSc
    return PETSc


def initialise(command_line_options):
    """Start PETSc with the command-line options (e.g. ``-pressure_ksp_rtol 1e-10``)."""
    import petsc4py
    petsc4py.init(["parmps"] + list(command_line_options))
    petsc4py._parmps_initialised = True


# Code defaults per preconditioner, measured on the 40k-particle dam break:
# dropping weak couplings below 0.04 when aggregating halves CG iterations and
# makes set-ups cheaper; one Chebyshev sweep per level instead of two costs ~2.5
# more CG iterations but ~11 % less solve time (paired runs of scripts/bench.py).
CODE_DEFAULTS = {"gamg": {"pc_gamg_threshold": "0.04", "mg_levels_ksp_max_it": "1"}}


def option_values(settings, on_command_line):
    """The PETSc options (names without the prefix) to put in the options database.

    Precedence, lowest first: the code's defaults for the chosen preconditioner,
    the case's ``[pressure] options`` (names with or without a leading dash), the
    command line (``on_command_line(name)`` says whether it set a name; those
    are left alone), then ``setFromOptions``.
    """
    case_options = {name.lstrip("-"): (str(value).lower() if isinstance(value, bool) else value)
                    for name, value in settings["options"].items()}
    merged = dict(CODE_DEFAULTS.get(settings["pc_type"], {}), **case_options)
    return {name: value for name, value in merged.items() if not on_command_line(name)}


class PressureSolver:
    """One KSP (CG + GAMG by default) reused for every step's pressure system."""

    def __init__(self, comm, settings):
        PETSc = _petsc()
        self.PETSc = PETSc
        self.comm = comm
        options = PETSc.Options()
        for name, value in option_values(
                settings, lambda name: options.hasName(OPTIONS_PREFIX + name)).items():
            options.setValue(OPTIONS_PREFIX + name, value)
        self.settings = settings
        self.ksp = self._make_ksp()
        self.sizes = None
        self.solves = 0
        self.reuse_limit = settings["reuse_preconditioner"]
        self.preconditioner_age = 0
        self.fresh_iterations = None
        self.last_iterations = 0
        self.setups = 0

    def _make_ksp(self):
        settings = self.settings
        ksp = self.PETSc.KSP().create(comm=self.comm)
        ksp.setOptionsPrefix(OPTIONS_PREFIX)
        ksp.setType(settings["ksp_type"])
        ksp.getPC().setType(settings["pc_type"])
        ksp.setTolerances(rtol=settings["rtol"], atol=1e-50, max_it=settings["max_iterations"])
        ksp.setInitialGuessNonzero(True)
        ksp.setFromOptions()
        return ksp

    def describe(self):
        return (f"KSP {self.ksp.getType()} + PC {self.ksp.getPC().getType()}, "
                f"rtol {self.ksp.getTolerances()[0]:g}")

    def solve(self, indptr, columns, values, rhs, guess, step):
        """Solve A p = rhs for this rank's rows; returns (p, iterations, residual norm).

        indptr/columns/values: CSR of the local rows with global column numbers.
        """
        PETSc = self.PETSc
        n_local = len(rhs)
        index_type = PETSc.IntType
        matrix = PETSc.Mat().createAIJ(
            size=((n_local, PETSc.DETERMINE), (n_local, PETSc.DETERMINE)),
            csr=(indptr.astype(index_type), columns.astype(index_type),
                 values.astype(PETSc.ScalarType)),
            comm=self.comm)
        matrix.setOption(PETSc.Mat.Option.SYMMETRIC, True)
        matrix.assemble()
        b = matrix.createVecLeft()
        x = matrix.createVecRight()
        b.getArray()[:] = rhs
        x.getArray()[:] = guess
        # Collective: every rank must rebuild the KSP together, or PETSc hangs.
        if self.comm.allreduce(int(matrix.getSizes() != self.sizes)) > 0:
            # Migration changed this rank's rows; a preconditioner (GAMG) cannot
            # change size, so start afresh.
            self.ksp.destroy()
            self.ksp = self._make_ksp()
            self.sizes = matrix.getSizes()
            self.fresh_iterations = None
        # The AMG hierarchy of a recent matrix preconditions this one well while
        # particles move little; set it up again every few steps, or sooner when
        # CG needs clearly more iterations than right after a set-up.
        reuse = (self.fresh_iterations is not None
                 and self.preconditioner_age < self.reuse_limit
                 and self.last_iterations <= 1.5 * self.fresh_iterations + 2)
        self.ksp.getPC().setReusePreconditioner(reuse)
        self.ksp.setOperators(matrix)
        self.ksp.solve(b, x)
        reason = self.ksp.getConvergedReason()
        iterations = self.ksp.getIterationNumber()
        residual = self.ksp.getResidualNorm()
        solution = x.getArray().copy()
        self.last_iterations = iterations
        if reuse:
            self.preconditioner_age += 1
        else:
            self.preconditioner_age = 0
            self.fresh_iterations = iterations
            self.setups += 1
        for item in (matrix, b, x):
            item.destroy()
        self.solves += 1
        if reason < 0:
            raise RunFailure(f"pressure solve diverged at step {step}: {_reason_name(PETSc, reason)}"
                             f" after {iterations} iterations (residual {residual:.3e})")
        return solution, iterations, residual

    def destroy(self):
        self.ksp.destroy()


def _reason_name(PETSc, reason):
    for name in dir(PETSc.KSP.ConvergedReason):
        if not name.startswith("_") and getattr(PETSc.KSP.ConvergedReason, name) == reason:
            return f"{name} ({reason})"
    return f"KSP reason {reason}"
