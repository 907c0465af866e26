"""What every compiled pair loop shares, in d = 2 or 3 dimensions: the pair's distance and
components, the MPS weights, and :func:`for_each_dimension`, which makes a loop's public
kernel.

The loops themselves sit beside what they compute: the number density here in
:mod:`parmps.core.density`, the sub-lists of a pair list in :mod:`parmps.core.neighbours`,
the pressure matrix's rows with the Laplacian (:mod:`parmps.fluid.schemes.laplacian`), the
gradient and its corrections (:mod:`parmps.fluid.schemes.gradient`), the free surface's
(:mod:`parmps.fluid.schemes.surface`), the shifting's (:mod:`parmps.fluid.schemes.shifting`),
the divergence (:mod:`parmps.fluid.schemes.mixed`), the viscous term and the no-slip wall
(:mod:`parmps.fluid.viscous`), the collisions (:mod:`parmps.fluid.collisions`). Each
computes the sums of :mod:`parmps.core.operators` row by row over the CSR pair lists with
distances evaluated on the fly: each pair is visited once per operator and nothing is
allocated per pair. The numpy operators stay as the reference the tests compare against.

Positions and vector fields are (N, d) arrays; d is ``position.shape[1]``.

How the loops are written:

* Every pair is visited through one prologue, :func:`pair_distance2` (|r_ij|^2)
  and :func:`pair_component` (component k of r_ij = x_j - x_i). Component sums run
  over k = 0, 1, ... in order, so in 2D every result is bit for bit what the
  former explicit x/y code gave (0.0 + a + b == a + b; no dot products, no
  sqrt-then-square).
* A loop is written once, with the dimension ``d`` its first argument, and decorated with
  :func:`for_each_dimension`: the public kernel it makes calls the loop (inlined) with d
  a literal 2 or 3, so numba compiles one copy per dimension in which the component loops
  have a constant trip count and unroll (with d read at run time inside the pair loop
  the kernels were 15-20 % slower).
* numba's cache (``cache=True``) notices an edit to a kernel's own file, not to a module
  whose functions it inlines: after editing this module, clear the ``__pycache__``
  entries (``*.nbi``, ``*.nbc``) of the kernels that use it.
"""

import inspect

import numba
import numpy as np


@numba.njit(cache=True)
def check_dimension(d):
    """Refuse positions of other than 2 or 3 components."""
    if d != 2 and d != 3:
        raise ValueError("parmps kernels: positions must have 2 or 3 components")


def for_each_dimension(loop):
    """The public kernel of ``loop``, a pair loop whose first argument is the dimension d.

    The kernel takes the loop's other arguments (their defaults too), checks that
    ``position`` has 2 or 3 components and calls the loop, inlined, with d the literal 2 or
    3. Its source is generated from the loop's signature and compiled under the loop's
    file, so that numba caches it there (numba caches no function without a source file).
    """
    parameters = list(inspect.signature(loop).parameters.values())
    if parameters[0].name != "d" or "position" not in [p.name for p in parameters]:
        raise TypeError(f"{loop.__name__}: a pair loop takes d first and a 'position'")
    declared = ", ".join(str(p) for p in parameters[1:])

    def call(d):
        return ", ".join([str(d)] + [p.name for p in parameters[1:]])

    source = (f"def {loop.__name__}({declared}):\n"
              f"    check_dimension(position.shape[1])\n"
              f"    if position.shape[1] == 2:\n"
              f"        return loop({call(2)})\n"
              f"    return loop({call(3)})\n")
    namespace = {"loop": numba.njit(cache=True, inline="always")(loop),
                 "check_dimension": check_dimension, "__name__": loop.__module__}
    exec(compile(source, inspect.getfile(loop), "exec"), namespace)
    kernel = namespace[loop.__name__]
    kernel.__doc__ = loop.__doc__
    return numba.njit(cache=True)(kernel)


@numba.njit(cache=True, inline="always")
def weight(distance, radius):
    """The MPS weight re/r - 1 of a pair at ``distance`` within ``radius`` re, else 0."""
    if distance <= 0.0 or distance >= radius:
        return 0.0
    return radius / distance - 1.0


# A relative margin on r^2 for cuts made before the square root (pairs_within, and
# weight_of_r2's early exit): a kernel tests its radius as sqrt(r^2) < radius or
# r^2 < radius^2, which can disagree in the last bit, so a cut this much wider keeps
# every pair any kernel would weigh, and their sums stay bit for bit the same.
PAIRS_WITHIN_MARGIN = 1e-12


@numba.njit(cache=True, inline="always")
def weight_of_r2(r2, radius):
    """weight(sqrt(r2), radius), without the square root for pairs clearly outside."""
    if r2 >= radius * radius * (1.0 + PAIRS_WITHIN_MARGIN):
        return 0.0
    return weight(np.sqrt(r2), radius)


@numba.njit(cache=True, inline="always")
def pair_distance2(position, i, j, d):
    """|r_ij|^2 for r_ij = x_j - x_i, summed over the d components in order."""
    r2 = 0.0
    for k in range(d):
        delta = position[j, k] - position[i, k]
        r2 += delta * delta
    return r2


@numba.njit(cache=True, inline="always")
def pair_component(position, i, j, k):
    """Component k of r_ij = x_j - x_i (the very value :func:`pair_distance2` squares)."""
    return position[j, k] - position[i, k]


@numba.njit(cache=True, inline="always")
def wendland(q):
    """Wendland's C2 function (1 - q)^4 (1 + 4q) of q = r / support, 0 from q = 1 on:
    smooth and finite at r = 0 (the density measure of the sources, the probes' weight)."""
    if q >= 1.0:
        return 0.0
    a = 1.0 - q
    return a * a * a * a * (1.0 + 4.0 * q)


@numba.njit(cache=True, inline="always")
def row_length(vectors, i, d):
    """The Euclidean length of row i of ``vectors`` (its first d components)."""
    total = 0.0
    for k in range(d):
        total += vectors[i, k] * vectors[i, k]
    return np.sqrt(total)


@numba.njit(cache=True, inline="always")
def laplacian_weight(r2, radius, inverse_cube):
    # The standard MPS weight re/r - 1, or Khayyer & Gotoh's (2010) higher-order
    # one re/r^3, for 0 < r < re; 0 outside.
    if r2 <= 0.0 or r2 >= radius * radius:
        return 0.0
    if inverse_cube:
        return radius / (r2 * np.sqrt(r2))
    return radius / np.sqrt(r2) - 1.0

