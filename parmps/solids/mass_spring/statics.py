"""Linear statics and vibration of a spring network: the stiffness matrix at rest, its solve,
its lowest modes and its highest frequency (the substep's stability limit).

For verification (patch tests, beams, plates) and for starting a run from equilibrium:
the same springs the time integrator uses, linearised about their rest state, where a
spring between i and j with unit vector e contributes k e e^T to the (i, i) and (j, j)
blocks and -k e e^T to (i, j) and (j, i). Any dimension d; the matrix is sparse (scipy
CSR, dofs ordered x0, y0[, z0], x1, ...), solved by sparse direct factors (SuperLU): a
beam of 18,100 nodes in about 5 s, a plate quadrant of 14,884 nodes in about 15 s on these
machines.
"""

import math

import numpy as np
import scipy.sparse as sparse
import scipy.sparse.linalg as sparse_linalg
from scipy.sparse.csgraph import reverse_cuthill_mckee

# Banded factors are used when, renumbered by reverse Cuthill-McKee, the matrix's envelope
# holds fewer than this many entries per non-zero: a body long in one direction (a beam:
# about 11 for 10 x 10 nodes across, L/h = 20) factors with far less fill that way than with
# SuperLU's COLAMD ordering (35 M against 113 M entries); a plate or a block does not (32).
BAND_FILL_LIMIT = 20.0


def stiffness_matrix(position, springs, stiffness):
    """The (d n, d n) linear stiffness matrix K (scipy CSR), dofs ordered (x0, y0, ..., x1, ...)."""
    n, d = position.shape
    separation = position[springs[:, 1]] - position[springs[:, 0]]
    direction = separation / np.linalg.norm(separation, axis=1)[:, None]
    block = stiffness[:, None, None] * direction[:, :, None] * direction[:, None, :]
    component = np.arange(d)
    shape = block.shape
    rows, columns, values = [], [], []
    for first, second, sign in ((0, 0, 1.0), (1, 1, 1.0), (0, 1, -1.0), (1, 0, -1.0)):
        rows.append(np.broadcast_to(d * springs[:, first, None, None] + component[:, None],
                                    shape))
        columns.append(np.broadcast_to(d * springs[:, second, None, None] + component, shape))
        values.append(sign * block)
    # COO sums the duplicate entries of the springs meeting at a node.
    matrix = sparse.coo_matrix((np.concatenate(values).ravel(),
                                (np.concatenate(rows).ravel(), np.concatenate(columns).ravel())),
                               shape=(d * n, d * n))
    return matrix.tocsr()


def _dof_mask(fixed, n, d):
    """``fixed`` (n,) per node or (n, d) per dof, as a flat (d n,) mask."""
    return np.broadcast_to(np.asarray(fixed, bool).reshape(n, -1), (n, d)).ravel()


def factorise(matrix):
    """A solve with the sparse symmetric positive definite ``matrix``: a function b -> x.

    SuperLU factors, in reverse Cuthill-McKee order when that order's envelope is small
    (:data:`BAND_FILL_LIMIT`), else with SuperLU's own COLAMD column ordering.
    """
    matrix = sparse.csr_matrix(matrix)
    order = reverse_cuthill_mckee(matrix, symmetric_mode=True)
    banded = matrix[order][:, order].tocsr()
    # Each row's first column: the envelope the banded factors fill.
    first = np.minimum.reduceat(banded.indices, banded.indptr[:-1])
    envelope = float(np.sum(np.arange(banded.shape[0]) - first))
    if 2.0 * envelope < BAND_FILL_LIMIT * matrix.nnz:
        factors = sparse_linalg.splu(banded.tocsc(), permc_spec="NATURAL")
        inverse = np.argsort(order)
        return lambda rhs: factors.solve(np.asarray(rhs)[order])[inverse]
    factors = sparse_linalg.splu(matrix.tocsc(), permc_spec="COLAMD")
    return factors.solve


def static_displacement(matrix, force, fixed, prescribed=None):
    """Displacements (n, d) solving K u = F on the free dofs.

    ``matrix``: K (sparse or dense); ``force`` (n, d) acts on the nodes; ``fixed``
    (n,) or (n, d) marks nodes or single dofs held at ``prescribed`` (n, d; default
    zero). Also returns the reactions (n, d): the forces the supports exert, K u - F
    on the fixed dofs.
    """
    force = np.asarray(force, float)
    n, d = force.shape
    matrix = sparse.csr_matrix(matrix)
    fixed = _dof_mask(fixed, n, d)
    free = ~fixed
    u = np.zeros(d * n) if prescribed is None else np.asarray(prescribed, float).ravel().copy()
    u[free] = 0.0
    rhs = force.ravel()[free] - matrix[free][:, fixed] @ u[fixed]
    u[free] = factorise(matrix[free][:, free])(rhs)
    reaction = matrix @ u - force.ravel()
    reaction[free] = 0.0
    return u.reshape(n, d), reaction.reshape(n, d)


def lowest_frequencies(matrix, mass, fixed, count=1):
    """The ``count`` lowest angular frequencies [rad/s] of K phi = omega^2 M phi, and their
    mode shapes (count, n, d; zero on the fixed dofs).

    ``mass`` (n,) the node masses (M is diagonal: mass per dof); ``fixed`` as in
    :func:`static_displacement`. A sparse generalised eigen solve (ARPACK, shift-invert
    about 0), so the lowest modes of a large body come without a dense matrix.
    """
    mass = np.asarray(mass, float)
    n = len(mass)
    d = matrix.shape[0] // n
    free = ~_dof_mask(fixed, n, d)
    stiffness = sparse.csr_matrix(matrix)[free][:, free].tocsc()
    masses = sparse.diags(np.repeat(mass, d)[free]).tocsc()
    # Shift-invert about 0 needs K^-1: the same factors as the statics.
    solve = factorise(stiffness)
    inverse = sparse_linalg.LinearOperator(stiffness.shape, matvec=solve, dtype=float)
    values, vectors = sparse_linalg.eigsh(stiffness, k=count, M=masses, sigma=0.0, which="LM",
                                          OPinv=inverse)
    order = np.argsort(values)
    shapes = np.zeros((count, d * n))
    shapes[:, free] = vectors[:, order].T
    return np.sqrt(np.abs(values[order])), shapes.reshape(count, n, d)


# Below this many dofs the highest frequency comes from a dense eigen solve (ARPACK needs
# more dofs than the one value it is asked for, and a small dense solve is as fast).
DENSE_DOFS = 600


def highest_frequency(matrix, mass):
    """The highest angular frequency [rad/s] of K phi = omega^2 M phi with every dof free.

    ``mass`` (n,) the node masses. Fixing dofs can only lower it (the fixed problem's
    M^-1/2 K M^-1/2 is a principal submatrix of the free one's), so it bounds a body with
    supports too. Lanczos (ARPACK) on M^-1/2 K M^-1/2 from a fixed start vector, so that
    every rank finds the same value for the same body; a dense solve for small bodies.
    """
    mass = np.asarray(mass, float)
    n = len(mass)
    if n == 0 or matrix.shape[0] == 0:
        return 0.0
    d = matrix.shape[0] // n
    scale = sparse.diags(1.0 / np.sqrt(np.repeat(mass, d)))
    scaled = (scale @ sparse.csr_matrix(matrix) @ scale).tocsr()
    if scaled.shape[0] <= DENSE_DOFS:
        largest = float(np.linalg.eigvalsh(scaled.toarray())[-1])
    else:
        start = np.random.default_rng(0).standard_normal(scaled.shape[0])
        largest = float(sparse_linalg.eigsh(scaled, k=1, which="LA", v0=start, tol=1e-8,
                                            return_eigenvectors=False)[0])
    return math.sqrt(max(largest, 0.0))


def body_static_displacement(body, time=0.0):
    """Linear static displacement of a :class:`Body` under its external force at ``time``.

    Pinned nodes stay fixed; the volume constraint is not included (switch it off
    for a body whose static state is compared with this).
    """
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    displacement, _ = static_displacement(matrix, body.external_force(time), body.pinned)
    return displacement
