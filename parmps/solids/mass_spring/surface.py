"""The gradient of the volume a closed boundary encloses, in any dimension d (the volume
itself is :func:`parmps.geometry.mesh.enclosed_volume`).

A body's boundary is a set of facets, each d node indices in an order that
makes it face outward: in 2D the edges (i, i+1) of the counter-clockwise loop,
in 3D triangles whose normal (x_b - x_a) x (x_c - x_a) points out. The
enclosed volume (the area in 2D) is the divergence theorem's sum of the signed
simplices the facets span with a common apex,

    V = 1/d! sum_facets det[x_a; x_b (; x_c)]

(2D: 1/2 sum (x_i y_j - x_j y_i), the polygon area; 3D: 1/6 sum (x_a x x_b).x_c),
and, since a determinant is linear in each row, its gradient is the facets'
cofactor rows,

    dV/dx_i = 1/d! sum_{facets containing i} cof_i(facet)

(2D: (y_{i+1} - y_{i-1}, x_{i-1} - x_{i+1})/2; 3D: 1/6 sum x_j x x_k with (i, j, k)
the triangle's cyclic order, = 1/3 sum A_t n_t). Nodes on no facet get zero.

For a closed boundary the apex is arbitrary; both functions put it at the first
facet's first node rather than at the origin, which gives the same numbers
without the cancellation of large terms for a small body far from the origin.
"""

import math

import numpy as np

# The volume itself is the geometry's (parmps.geometry.mesh); its gradient is the body's.
from parmps.geometry.mesh import _corners, _permutations


def volume_gradient(position, facets):
    """dV/dx (n, d): 1/d! times the sum of the cofactor rows of the facets on each node."""
    position = np.asarray(position, dtype=float)
    facets = np.asarray(facets, dtype=np.int64)
    x = _corners(position, facets)
    m, d = len(facets), position.shape[1]
    cofactor = np.zeros((m, d, d))
    for p, sign in _permutations(d):
        for r in range(d):
            # The term of this permutation without its factor from row r.
            term = np.full(m, sign)
            for s in range(d):
                if s != r:
                    term = term * x[:, s, p[s]]
            cofactor[:, r, p[r]] += term
    n = len(position)
    nodes = facets.ravel()
    rows = cofactor.reshape(m * d, d)
    gradient = np.empty((n, d))
    for axis in range(d):
        gradient[:, axis] = np.bincount(nodes, weights=rows[:, axis], minlength=n)
    return gradient / math.factorial(d)
