"""A preconditioner set up on one layout of the pressure rows, applied to a later layout.

The rows of the pressure system are particles, and a particle's row moves when it changes
rank (migration) or when a rank's rows are numbered afresh. A preconditioner (GAMG) is set up
for one layout and cannot change size, so each new layout used to force a set-up of its own
even while the policy (:func:`parmps.fluid.ppe.keep_preconditioner`) would have kept it: in
the 2D dam break at 40k particles, 2 ranks set up 8 times in 65 steps against 5 on one rank.

Here the rows are matched by their identity (the particle's id): a residual in the new layout
is moved into the set-up's layout, preconditioned there, and moved back; a row that was not in
the set-up's layout (new since) is preconditioned by its diagonal alone. The operator is
``S^T M S + D^-1`` on the rows not matched, with S the matching and M the kept
preconditioner: symmetric and positive whenever M is, as CG needs. For the rows that stayed
where they were it is M itself.

A kept GAMG hierarchy applies a matrix on its finest level only (its smoother and residual),
and holds none between solves (:meth:`parmps.fluid.ppe.PressureSolver._let_go`): on a later
layout that level applies this step's matrix seen in the set-up's layout, ``S A S^T`` on the
rows matched and the set-up's own diagonal on the rows that have none now
(:class:`OnSetupLayout`), symmetric and positive as A is.
"""

import numpy as np


class RelaidPreconditioner:
    """PETSc's Python-PC context: ``setup_pc`` (set up on the layout whose rows, rank by rank,
    were ``setup_ids`` from global row ``setup_first``, and whose matrix's diagonal was
    ``setup_diagonal``) applied to the rows ``ids`` of a new layout, ``matrix`` the new
    layout's matrix (its diagonal for the unmatched rows). With ``finest_level``, ``operator``
    is this step's matrix in the set-up's layout, for the set-up's finest level to apply.
    Collective: every rank makes it together."""

    def __init__(self, PETSc, comm, setup_pc, setup_diagonal, setup_ids, setup_first, ids,
                 matrix, finest_level=False):
        self.PETSc = PETSc
        self.pc = setup_pc
        # Applied as it was set up, whatever matrix its KSP points at.
        setup_pc.setReusePreconditioner(True)
        old_rows = setup_rows_of(PETSc, comm, setup_ids, setup_first, ids)
        first = matrix.getOwnershipRange()[0]
        matched = old_rows >= 0
        self.x_old, self.y_old = setup_diagonal.duplicate(), setup_diagonal.duplicate()
        x_new = matrix.createVecLeft()
        index_type = PETSc.IntType
        to_new = PETSc.IS().createGeneral(
            (first + np.flatnonzero(matched)).astype(index_type), comm=comm)
        to_old = PETSc.IS().createGeneral(old_rows[matched].astype(index_type), comm=comm)
        self.scatter = PETSc.Scatter().create(x_new, to_new, self.x_old, to_old)
        for item in (to_new, to_old, x_new):
            item.destroy()
        self.unmatched = ~matched
        # A vector is made on every rank or none (collective).
        any_unmatched = comm.allreduce(int(self.unmatched.any())) > 0
        self.jacobi = matrix.createVecLeft() if any_unmatched else None
        self.on_setup_layout = None
        self.operator = None
        if finest_level:
            self.on_setup_layout = OnSetupLayout(PETSc, self.scatter, setup_diagonal, matrix)
            sizes = setup_diagonal.getSizes()
            self.operator = PETSc.Mat().createPython(
                (sizes, sizes), self.on_setup_layout, comm=comm)
            self.operator.setUp()

    def use(self, matrix):
        """This step's matrix (the same layout): its diagonal for the unmatched rows, and the
        operator's matrix; None once the step is done with it."""
        if self.on_setup_layout is not None:
            self.on_setup_layout.matrix = matrix
        if matrix is not None and self.jacobi is not None:
            matrix.getDiagonal(self.jacobi)
            array = self.jacobi.getArray()
            inverse = np.zeros_like(array)
            inverse[self.unmatched] = 1.0 / array[self.unmatched]
            array[:] = inverse

    def apply(self, pc, x, y):
        """y = M x, through the set-up's layout (PETSc calls this once a CG iteration)."""
        PETSc = self.PETSc
        self.x_old.zeroEntries()
        self.scatter.scatter(x, self.x_old, PETSc.InsertMode.INSERT_VALUES,
                             PETSc.ScatterMode.FORWARD)
        self.pc.apply(self.x_old, self.y_old)
        if self.jacobi is not None:
            y.pointwiseMult(x, self.jacobi)
        else:
            y.zeroEntries()
        self.scatter.scatter(self.y_old, y, PETSc.InsertMode.INSERT_VALUES,
                             PETSc.ScatterMode.REVERSE)

    def release(self):
        """Free the PETSc objects (not ``destroy``: PETSc calls that of a Python PC's context
        when its PC goes, and this one outlives the PCs it serves)."""
        for item in (self.scatter, self.x_old, self.y_old, self.jacobi, self.operator):
            if item is not None:
                item.destroy()
        if self.on_setup_layout is not None:
            self.on_setup_layout.release()


class OnSetupLayout:
    """PETSc's Python-matrix context: the step's ``matrix`` (a later layout) seen in the
    set-up's layout through ``scatter`` (later layout -> set-up's, forward), ``S A S^T`` on
    the set-up's rows matched now and ``setup_diagonal`` on those unmatched."""

    def __init__(self, PETSc, scatter, setup_diagonal, matrix):
        self.PETSc = PETSc
        self.scatter = scatter
        self.matrix = matrix
        self.x_new, self.y_new = matrix.createVecs()
        # The set-up's diagonal on its rows that have no row now, 0 on the others.
        ones, seen = matrix.createVecLeft(), setup_diagonal.duplicate()
        ones.set(1.0)
        seen.zeroEntries()
        scatter.scatter(ones, seen, PETSc.InsertMode.INSERT_VALUES, PETSc.ScatterMode.FORWARD)
        self.unmatched_diagonal = setup_diagonal.copy()
        self.unmatched_diagonal.getArray()[seen.getArray() != 0.0] = 0.0
        for item in (ones, seen):
            item.destroy()

    def mult(self, mat, x, y):
        PETSc = self.PETSc
        self.x_new.zeroEntries()
        self.scatter.scatter(x, self.x_new, PETSc.InsertMode.INSERT_VALUES,
                             PETSc.ScatterMode.REVERSE)
        self.matrix.mult(self.x_new, self.y_new)
        y.pointwiseMult(x, self.unmatched_diagonal)
        self.scatter.scatter(self.y_new, y, PETSc.InsertMode.INSERT_VALUES,
                             PETSc.ScatterMode.FORWARD)

    def getDiagonal(self, mat, diagonal):
        self.matrix.getDiagonal(self.y_new)
        self.unmatched_diagonal.copy(diagonal)
        self.scatter.scatter(self.y_new, diagonal, self.PETSc.InsertMode.INSERT_VALUES,
                             self.PETSc.ScatterMode.FORWARD)

    def release(self):
        for item in (self.x_new, self.y_new, self.unmatched_diagonal):
            item.destroy()
        self.matrix = None


def setup_rows_of(PETSc, comm, setup_ids, setup_first, ids):
    """The set-up's global row of each of ``ids`` (this rank's rows now), -1 for an id that
    had no row then. ``setup_ids``: this rank's rows' ids at the set-up, in row order from
    global row ``setup_first``. Collective: a directory indexed by id, spread over the ranks,
    filled by the set-up's owners and read by the new ones (one exchange each way)."""
    setup_ids = np.asarray(setup_ids, np.int64)
    ids = np.asarray(ids, np.int64)
    from mpi4py import MPI
    span = comm.allreduce(int(setup_ids.max()) + 1 if len(setup_ids) else 0, op=MPI.MAX)
    directory = PETSc.Vec().createMPI((PETSc.DECIDE, max(span, 1)), comm=comm)
    directory.set(-1.0)
    index_type = PETSc.IntType
    # Row numbers as doubles: exact below 2^53.
    directory.setValues(setup_ids.astype(index_type),
                        (setup_first + np.arange(len(setup_ids))).astype(np.float64),
                        PETSc.InsertMode.INSERT_VALUES)
    directory.assemblyBegin()
    directory.assemblyEnd()
    known = ids < span
    wanted = PETSc.IS().createGeneral(ids[known].astype(index_type), comm=comm)
    found = PETSc.Vec().createSeq(int(known.sum()), comm=PETSc.COMM_SELF)
    gather = PETSc.Scatter().create(directory, wanted, found, None)
    gather.scatter(directory, found, PETSc.InsertMode.INSERT_VALUES,
                   PETSc.ScatterMode.FORWARD)
    rows = np.full(len(ids), -1, np.int64)
    rows[known] = np.rint(found.getArray()).astype(np.int64)
    for item in (gather, found, wanted, directory):
        item.destroy()
    return rows

