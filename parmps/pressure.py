"""The pressure Poisson equation on a distributed PETSc AIJ matrix (DESIGN.md §1.2, §2).

Rows are the owned unknowns, numbered contiguously per rank (offsets from an
exclusive scan); ghost unknowns carry their global row number. The matrix is
built whole-rows-at-once from CSR arrays; the KSP has the options prefix
``pressure_`` so the case file and the command line (``-pressure_ksp_rtol``)
reach it, in that order of precedence over the code's defaults.
"""

import logging

import numpy as np

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


class PressureSolver:
    """One KSP (CG + GAMG by default) reused for every step's pressure system."""

    def __init__(self, comm, settings):
        PETSc = _petsc()
        self.PETSc = PETSc
        self.comm = comm
        options = PETSc.Options()
        # Case-file options apply unless the command line already set the same name.
        for name, value in settings["options"].items():
            full = OPTIONS_PREFIX + name.lstrip("-")
            if not options.hasName(full):
                options.setValue(full, str(value).lower() if isinstance(value, bool) else value)
        self.settings = settings
        self.ksp = self._make_ksp()
        self.sizes = None
        self.solves = 0

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
            # The set of unknowns changes as particles reach or leave the free
            # surface; a preconditioner (GAMG) cannot change size, so start afresh.
            self.ksp.destroy()
            self.ksp = self._make_ksp()
            self.sizes = matrix.getSizes()
        self.ksp.setOperators(matrix)
        self.ksp.solve(b, x)
        reason = self.ksp.getConvergedReason()
        iterations = self.ksp.getIterationNumber()
        residual = self.ksp.getResidualNorm()
        solution = x.getArray().copy()
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


def assemble(rows, cols, w_laplacian, unknown_row, global_row, is_dummy,
             number_density, n0, laplacian_coefficient, density, dt, relaxation,
             compressibility):
    """CSR rows of the pressure Poisson equation for the owned unknowns.

    For unknown i:  sum_j a w_ij (P_i - P_j) + (rho c / dt^2) P_i
                    = (rho / dt^2) gamma (n*_i - n0) / n0,
    with a = 2d/(lambda0 n0), j over non-dummy neighbours; a Dirichlet (free
    surface) neighbour has P_j = 0 and adds to the diagonal only. The sign makes
    the matrix symmetric positive definite.

    unknown_row: bool per owned particle; global_row: per local particle (owned
    and ghost), -1 where P is not an unknown. Returns (indptr, columns, values,
    rhs) over the unknown rows in local order.
    """
    n_owned = len(unknown_row)
    active = unknown_row[rows] & (w_laplacian > 0.0) & ~is_dummy[cols]
    diagonal = laplacian_coefficient * np.bincount(rows[active], weights=w_laplacian[active],
                                                   minlength=n_owned)
    diagonal += density * compressibility / dt ** 2
    coupled = active & (global_row[cols] >= 0)
    coupled_rows = rows[coupled]
    off_count = np.bincount(coupled_rows, minlength=n_owned)
    unknown = np.flatnonzero(unknown_row)
    row_length = 1 + off_count[unknown]
    csr_indptr = np.zeros(len(unknown) + 1, np.int64)
    np.cumsum(row_length, out=csr_indptr[1:])
    columns = np.empty(csr_indptr[-1], np.int64)
    values = np.empty(csr_indptr[-1], np.float64)
    columns[csr_indptr[:-1]] = global_row[unknown]
    values[csr_indptr[:-1]] = diagonal[unknown]
    # Pairs are grouped by row, so an entry's place in its row is its rank among
    # the coupled pairs minus the row's first coupled pair.
    start_in_pairs = np.zeros(n_owned + 1, np.int64)
    np.cumsum(off_count, out=start_in_pairs[1:])
    local_unknown_index = np.full(n_owned, -1, np.int64)
    local_unknown_index[unknown] = np.arange(len(unknown))
    within_row = np.arange(len(coupled_rows)) - start_in_pairs[coupled_rows]
    place = csr_indptr[local_unknown_index[coupled_rows]] + 1 + within_row
    columns[place] = global_row[cols[coupled]]
    values[place] = -laplacian_coefficient * w_laplacian[coupled]
    rhs = (density / dt ** 2) * relaxation * (number_density[unknown] - n0) / n0
    return csr_indptr, columns, values, rhs
