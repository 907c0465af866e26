"""Linear statics of a spring network: the stiffness matrix at rest and its solve.

For verification (patch tests, beams) and for starting a run from equilibrium:
the same springs the time integrator uses, linearised about their rest state,
where a spring between i and j with unit vector e contributes k e e^T to the
(i, i) and (j, j) blocks and -k e e^T to (i, j) and (j, i). Dense: meant for
bodies of a few thousand nodes.
"""

import numpy as np


def stiffness_matrix(position, springs, stiffness):
    """The (2n, 2n) linear stiffness matrix K, dofs ordered (x0, y0, x1, y1, ...)."""
    n = len(position)
    separation = position[springs[:, 1]] - position[springs[:, 0]]
    direction = separation / np.linalg.norm(separation, axis=1)[:, None]
    block = stiffness[:, None, None] * direction[:, :, None] * direction[:, None, :]
    matrix = np.zeros((n, 2, n, 2))
    i, j = springs[:, 0], springs[:, 1]
    np.add.at(matrix, (i, slice(None), i, slice(None)), block)
    np.add.at(matrix, (j, slice(None), j, slice(None)), block)
    np.add.at(matrix, (i, slice(None), j, slice(None)), -block)
    np.add.at(matrix, (j, slice(None), i, slice(None)), -block)
    return matrix.reshape(2 * n, 2 * n)


def static_displacement(matrix, force, fixed, prescribed=None):
    """Displacements (n, 2) solving K u = F on the free dofs.

    ``force`` (n, 2) acts on the nodes; ``fixed`` (n,) or (n, 2) marks nodes or
    single dofs held at ``prescribed`` (n, 2; default zero). Also returns the
    reactions (n, 2): the forces the supports exert, K u - F on the fixed dofs.
    """
    n = len(force)
    fixed = np.broadcast_to(np.asarray(fixed, bool).reshape(n, -1), (n, 2)).ravel()
    free = ~fixed
    u = np.zeros(2 * n) if prescribed is None else np.asarray(prescribed, float).ravel().copy()
    u[free] = 0.0
    rhs = np.asarray(force, float).ravel()[free] - matrix[np.ix_(free, fixed)] @ u[fixed]
    u[free] = np.linalg.solve(matrix[np.ix_(free, free)], rhs)
    reaction = matrix @ u - np.asarray(force, float).ravel()
    reaction[free] = 0.0
    return u.reshape(n, 2), reaction.reshape(n, 2)


def body_static_displacement(body, time=0.0):
    """Linear static displacement of a :class:`Body` under its external force at ``time``.

    Pinned nodes stay fixed; the area constraint is not included (switch it off
    for a body whose static state is compared with this).
    """
    matrix = stiffness_matrix(body.position, body.springs, body.stiffness)
    displacement, _ = static_displacement(matrix, body.external_force(time), body.pinned)
    return displacement
