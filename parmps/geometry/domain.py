"""The domain: the box that holds the particles, and the axes along which it is periodic.

Along a periodic axis the domain's extent is the period: a particle that leaves through
one face enters at the other, and a particle near a face sees the particles near the
opposite face as if they lay beyond it (the decomposition's periodic images,
:mod:`parmps.parallel.periodic`). Everything that measures a distance between two points
that may lie on either side of a seam (springs, a body's volume, probes, checks) takes
the minimum image of their difference from here.
"""

import numpy as np

from parmps.errors import CaseError

AXIS_NAMES = "xyz"

# Two lattices line up when their offsets differ by less than this many spacings.
_ALIGNED = 1e-6


class Domain:
    """The box [lower, upper) and its periodic axes (indices, ascending)."""

    def __init__(self, lower, upper, periodic=()):
        self.lower = np.asarray(lower, dtype=np.float64)
        self.upper = np.asarray(upper, dtype=np.float64)
        self.dimension = len(self.lower)
        self.periodic = tuple(sorted(int(a) for a in periodic))
        self.period = self.upper - self.lower
        # Along every axis: the period where periodic, 0 (no image) elsewhere.
        self.image_period = np.zeros(self.dimension)
        self.image_period[list(self.periodic)] = self.period[list(self.periodic)]

    @classmethod
    def from_case(cls, case):
        """The case's [domain] (validated), its periodic axes by name."""
        domain = case["domain"]
        periodic = [AXIS_NAMES.index(name) for name in domain.get("periodic", ())]
        return cls(domain["lower"], domain["upper"], periodic)

    @property
    def is_periodic(self):
        return bool(self.periodic)

    def wrap(self, position, beyond=0.0):
        """Move the rows of ``position`` ((n, d), in place) that lie more than ``beyond``
        past a periodic face back by one period; returns how many rows moved."""
        moved = np.zeros(len(position), bool)
        for axis in self.periodic:
            column = position[:, axis]
            low = column < self.lower[axis] - beyond
            high = column >= self.upper[axis] + beyond
            column[low] += self.period[axis]
            column[high] -= self.period[axis]
            moved |= low | high
        return int(np.count_nonzero(moved))

    def wrapped(self, position):
        """A copy of ``position`` with every row inside the domain along the periodic axes."""
        position = np.array(position, dtype=np.float64)
        for axis in self.periodic:
            position[:, axis] = self.lower[axis] + np.mod(position[:, axis] - self.lower[axis],
                                                          self.period[axis])
        return position

    def images(self, position, width):
        """(index, shift) of the periodic images of the rows of ``position`` within ``width``
        of a periodic face: the shift that carries each beyond the opposite face, and the
        combinations of such shifts at corners (``position[index] + shift`` are the
        images)."""
        index = np.arange(len(position), dtype=np.int64)
        shift = np.zeros((len(position), self.dimension))
        for axis in self.periodic:
            coordinate = position[index, axis]
            low = np.flatnonzero(coordinate < self.lower[axis] + width)
            high = np.flatnonzero(coordinate >= self.upper[axis] - width)
            new_shift = np.concatenate([shift[low], shift[high]])
            new_shift[:len(low), axis] += self.period[axis]
            new_shift[len(low):, axis] -= self.period[axis]
            index = np.concatenate([index, index[low], index[high]])
            shift = np.concatenate([shift, new_shift])
        moved = np.any(shift != 0.0, axis=1)
        return index[moved], shift[moved]

    def minimum_image(self, delta):
        """``delta`` (differences of positions, (..., d)) with each periodic component
        brought within half a period of zero (a new array)."""
        delta = np.array(delta, dtype=np.float64)
        for axis in self.periodic:
            period = self.period[axis]
            delta[..., axis] -= period * np.round(delta[..., axis] / period)
        return delta

    def near(self, position, reference):
        """``position`` ((n, d)) with each row taken at its image nearest ``reference`` ((d,))
        along the periodic axes (a new array; the rows as they are if none is periodic)."""
        reference = np.asarray(reference, dtype=np.float64)
        return reference + self.minimum_image(np.asarray(position) - reference)

    def outside(self, position):
        """Which rows of ``position`` lie outside the box along an axis that is not periodic
        (a periodic axis has no outside)."""
        out = np.zeros(len(position), bool)
        for axis in range(self.dimension):
            if axis not in self.periodic:
                out |= (position[:, axis] < self.lower[axis]) | \
                       (position[:, axis] > self.upper[axis])
        return out

    def spans(self, lower, upper, axis, tolerance):
        """Whether the box [lower, upper] reaches both faces along ``axis`` (within
        ``tolerance``)."""
        return (abs(lower[axis] - self.lower[axis]) <= tolerance and
                abs(upper[axis] - self.upper[axis]) <= tolerance)

    def check_lattice(self, spacing, origin, halo_width):
        """Refuse (CaseError) a periodic axis whose period is not a whole number of
        spacings, whose faces are off the lattice's lines, or that is no longer than twice
        the halo width (a particle would meet its own image)."""
        for axis in self.periodic:
            name = AXIS_NAMES[axis]
            period = self.period[axis]
            cells = period / spacing
            if abs(cells - round(cells)) > _ALIGNED * max(1.0, cells):
                raise CaseError(f"domain.periodic: the period along {name} "
                                f"({period:g} m) is {cells:.6g} spacings; it must be a whole "
                                f"number of particles.spacing ({spacing:g} m)")
            offset = (self.lower[axis] - origin[axis]) / spacing
            if abs(offset - round(offset)) > _ALIGNED * max(1.0, abs(offset)):
                raise CaseError(f"domain.periodic: domain.lower.{name} ({self.lower[axis]:g}) "
                                f"is not on the lattice's lines particles.origin.{name} + k "
                                f"particles.spacing ({origin[axis]:g} + k {spacing:g})")
            if not period > 2.0 * halo_width:
                raise CaseError(f"domain.periodic: the period along {name} ({period:g} m) "
                                f"must exceed twice the halo width ({2 * halo_width:g} m: "
                                f"(mps.re_laplacian + parallel.halo_skin + "
                                f"parallel.migration_margin) x particles.spacing, twice)")

    def describe(self):
        if not self.periodic:
            return "no periodic axis"
        return "periodic along " + ", ".join(AXIS_NAMES[a] for a in self.periodic)
