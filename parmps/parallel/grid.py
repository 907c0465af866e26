"""The rank grid of a block decomposition: px x py (x pz) ranks over the domain's extent.

Pure arithmetic (no MPI), so the choice of decomposition can be made and tested
anywhere. MPI's ``Dims_create`` balances the factors of the rank count without
looking at the domain: on 4 ranks it gives 2 x 2 even for a channel four times
as long as high, whose ghosts 4 x 1 would halve. Here every factorisation of
the rank count into d factors is scored by the halo it would cost, for the
domain's extent and the halo width, and the cheapest one that fits wins (ties
go to the first in Dims_create's order, more ranks along the earlier axes).
"""

import itertools

import numpy as np


def factorisations(ranks, dimension):
    """Every (g_0, ..., g_{d-1}) of positive integers whose product is ``ranks``."""
    divisors = [k for k in range(1, ranks + 1) if ranks % k == 0]
    found = []
    for head in itertools.product(divisors, repeat=dimension - 1):
        rest, remainder = divmod(ranks, int(np.prod(head, dtype=np.int64)))
        if remainder == 0:
            found.append(tuple(head) + (rest,))
    # Dims_create's order first: non-increasing factors, more ranks along earlier axes.
    return sorted(set(found), key=lambda dims: tuple(-g for g in dims))


def capacities(lower, upper, min_width):
    """How many regions at least ``min_width`` wide fit along each axis (at least 1)."""
    extent = np.asarray(upper, np.float64) - np.asarray(lower, np.float64)
    return np.maximum(1, np.floor(extent / min_width * (1 + 1e-12)).astype(np.int64))


def ghost_ratio(dims, lower, upper, width):
    """Ghosts per owned particle of a uniform ``dims`` grid over the domain, for a uniform
    density: a region grown by ``width`` on each cut face over the region, minus one.
    Along an axis of g regions a region has 2 (g - 1) / g cut faces on average (the
    end ones have one). A model to compare layouts, not a prediction of counts."""
    extent = np.asarray(upper, np.float64) - np.asarray(lower, np.float64)
    dims = np.asarray(dims, np.float64)
    side = extent / dims
    grown = side + width * 2.0 * (dims - 1.0) / dims
    # An uncut axis grows by nothing, even when the extent along it is nil (a flat scene).
    factor = np.divide(grown, side, out=np.ones_like(side), where=dims > 1)
    return float(np.prod(factor) - 1.0)


def choose_grid(ranks, lower, upper, min_width, width):
    """The rank grid with the smallest :func:`ghost_ratio` among those whose every axis
    holds its regions, or None when none fits (too many ranks for the halo)."""
    fits = [dims for dims in factorisations(ranks, len(lower))
            if np.all(np.asarray(dims) <= capacities(lower, upper, min_width))]
    if not fits:
        return None
    return min(fits, key=lambda dims: ghost_ratio(dims, lower, upper, width))


def describe_grid(dims):
    return " x ".join(str(int(g)) for g in dims)
