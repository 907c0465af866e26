"""Where to cut for an even load: quantiles of the particles' work along an axis, shared
by every decomposition.

Each particle weighs its kind's work (``Decomposition.weights``); the cuts go at
the quantiles of that work, exactly on one rank's sorted copy of the scene
(:func:`gap_quantiles`, at the start) or from allreduced histograms while the run
goes on (:func:`histogram_quantiles`). A part may carry work beyond its particles
(``extra``: a body's substeps on its owner rank); it then gets that much less of the
particles' work (:func:`part_targets`).
"""

import numpy as np
from mpi4py import MPI

_HISTOGRAM_BINS = 1024


def part_targets(total, parts, extra=None):
    """The particles' work below each of the ``parts - 1`` interior cuts: every part's load
    (its particles' work plus its ``extra``) equal, none with less than no particles.
    ``extra``: each part's work beyond its particles (None: none)."""
    if extra is None or not np.any(extra):
        return total * (np.arange(1, parts) / parts)
    share = np.maximum((total + float(np.sum(extra))) / parts - np.asarray(extra, float), 0.0)
    # A part whose extra alone exceeds the mean takes no particles; the others share them.
    share *= (total / share.sum()) if share.sum() > 0 else 0.0
    return np.cumsum(share)[:-1]


def gap_quantiles(values, parts, lower, upper, weights=None, extra=None):
    """``parts + 1`` cuts of sorted ``values``: the bounds, then the gaps between distinct
    values nearest the quantiles of ``weights`` (each value's work, 1 if None; lattice
    columns stay whole), less each part's ``extra`` work (:func:`part_targets`)."""
    cuts = np.empty(parts + 1)
    cuts[0], cuts[-1] = lower, upper
    n = len(values)
    if parts == 1:
        return cuts
    if n < 2:
        cuts[1:-1] = np.linspace(lower, upper, parts + 1)[1:-1]
        return cuts
    # The work below each split position k (0 <= k <= n): k itself when unweighted.
    below = np.arange(n + 1.0) if weights is None else np.concatenate([[0.0],
                                                                       np.cumsum(weights)])
    gaps = np.flatnonzero(values[1:] > values[:-1]) + 1
    for i, target in enumerate(part_targets(below[-1], parts, extra), start=1):
        if len(gaps) == 0:  # every value the same: no split is possible
            cuts[i] = values[0]
            continue
        j = np.searchsorted(below[gaps], target)
        candidates = (gaps[max(j - 1, 0)], gaps[min(j, len(gaps) - 1)])
        k = min(candidates, key=lambda gap: (abs(below[gap] - target), gap))
        cuts[i] = 0.5 * (values[k - 1] + values[k])
    return cuts


def histogram_quantiles(comm, x, weights, group, groups, parts, old, extra=None):
    """Per group, ``parts + 1`` cuts of x at the quantiles of the work (``weights``) of the
    group's particles over all ranks (collective), less each part's ``extra`` work
    ((groups, parts), or None). ``old``: the current cuts, kept for a group with no
    particles or a single x. Returns the cuts and, per group, whether it was cut (it has
    more than one x)."""
    nb = _HISTOGRAM_BINS
    bounds = np.full((groups, 2), -np.inf)
    np.maximum.at(bounds[:, 0], group, -x)
    np.maximum.at(bounds[:, 1], group, x)
    comm.Allreduce(MPI.IN_PLACE, bounds, op=MPI.MAX)
    x_min, x_max = -bounds[:, 0], bounds[:, 1]
    usable = x_max > x_min
    width = np.where(usable, (x_max - x_min) / nb, 1.0)
    coarse_index = np.clip(((x - x_min[group]) / width[group]).astype(np.int64), 0, nb - 1)
    # float even when empty: np.bincount gives int64 then, which Allreduce would mix.
    coarse = np.bincount(group * nb + coarse_index, weights,
                         minlength=groups * nb).astype(np.float64).reshape(groups, nb)
    comm.Allreduce(MPI.IN_PLACE, coarse, op=MPI.SUM)
    cumulative = np.concatenate([np.zeros((groups, 1)), np.cumsum(coarse, axis=1)], axis=1)
    targets = np.array([part_targets(cumulative[index, -1], parts,
                                     None if extra is None else extra[index])
                        for index in range(groups)]).reshape(groups, parts - 1)
    bins = np.empty((groups, parts - 1), np.int64)
    for index in range(groups):
        found = np.searchsorted(cumulative[index], targets[index], side="right") - 1
        bins[index] = np.clip(found, 0, nb - 1)
    # Refine each target's coarse bin into nb sub-bins (one allreduce for all).
    fine = np.zeros((groups, parts - 1, nb))
    fine_width = width / nb
    for index in range(groups):
        mine = group == index
        for row, b in enumerate(bins[index]):
            inside = mine & (coarse_index == b)
            start = x_min[index] + b * width[index]
            sub = np.clip(((x[inside] - start) / fine_width[index]).astype(np.int64), 0, nb - 1)
            fine[index, row] = np.bincount(sub, weights[inside], minlength=nb)
    comm.Allreduce(MPI.IN_PLACE, fine, op=MPI.SUM)
    cuts = old.copy()
    for index in range(groups):
        if not usable[index]:
            continue
        for row, (b, target) in enumerate(zip(bins[index], targets[index])):
            below = cumulative[index, b] + np.concatenate([[0], np.cumsum(fine[index, row])])
            j = int(np.argmin(np.abs(below - target)))
            cuts[index, row + 1] = x_min[index] + b * width[index] + j * fine_width[index]
    return cuts, usable
