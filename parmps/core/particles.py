"""The per-rank particle arrays: owned particles first, then ghosts.

Every rank holds its owned particles in slots [0, n_owned) and copies of
neighbouring ranks' particles (ghosts) after them. Global ids are int64, set when
the scene is built, and never change, so runs on different rank counts can be
compared particle by particle.

Vector fields (position, velocity) have one column per dimension d: the
trailing shape ("d",) in FIELDS stands for (d,). A Particles takes d from the
vector arrays it is given, or from ``dimension`` (2 when neither says).
"""

import numpy as np

FLUID, WALL, DUMMY, SOLID, INFLOW = 0, 1, 2, 3, 4
KIND_NAMES = {FLUID: "fluid", WALL: "wall", DUMMY: "dummy", SOLID: "solid node",
              INFLOW: "inflow buffer"}

# The dimension when nothing else tells it (no position given): a case's is that of its
# domain.lower, 2 or 3.
DEFAULT_DIMENSION = 2

# name -> (dtype, trailing shape, fill value for new particles); "d" in a shape
# is the dimension. The order is the packing order of the decomposition.
FIELDS = {
    "id": (np.int64, (), -1),
    "kind": (np.int8, (), FLUID),
    "position": (np.float64, ("d",), 0.0),
    "velocity": (np.float64, ("d",), 0.0),
    "pressure": (np.float64, (), 0.0),
    "number_density": (np.float64, (), 0.0),
    # 1: a wall away from the water, which took no part in the last fluid step (no pair
    # list, P = 0); the load balance weighs it as a dummy. Set by the fluid each step.
    "dry": (np.int8, (), 0),
    # Solid bodies: index of the body (-1 for none) and of the node within it.
    "body": (np.int32, (), -1),
    "node": (np.int32, (), -1),
}


def particle_fields(dimension):
    """FIELDS with the trailing shapes of d = ``dimension``: name -> (dtype, shape, fill)."""
    return {name: (dtype, tuple(dimension if axis == "d" else axis for axis in shape), fill)
            for name, (dtype, shape, fill) in FIELDS.items()}


def _dimension_of(arrays):
    """d from the first vector field present in ``arrays`` (None if there is none)."""
    for name, (_, shape, _) in FIELDS.items():
        if "d" in shape and name in arrays:
            array = np.asarray(arrays[name])
            if array.ndim == 1 + len(shape):
                return int(array.shape[1 + shape.index("d")])
    return None


class Particles:
    """Arrays of FIELDS with the owned particles first; ``n_owned`` marks where ghosts start.

    ``dimension``: d, when the arrays given hold no vector field to take it from.
    """

    def __init__(self, arrays, n_owned=None, dimension=None):
        size = len(arrays["id"])
        given = _dimension_of(arrays)
        if dimension is None:
            dimension = DEFAULT_DIMENSION if given is None else given
        self.dimension = int(dimension)
        self.arrays = {}
        for name, (dtype, shape, fill) in particle_fields(self.dimension).items():
            if name in arrays:
                array = np.ascontiguousarray(arrays[name], dtype=dtype)
                if array.shape != (size,) + shape:
                    raise ValueError(f"field {name} has shape {array.shape}, "
                                     f"expected {(size,) + shape}")
            else:
                array = np.full((size,) + shape, fill, dtype=dtype)
            self.arrays[name] = array
        self.n_owned = size if n_owned is None else int(n_owned)

    @classmethod
    def empty(cls, dimension=DEFAULT_DIMENSION):
        return cls({name: np.empty((0,) + shape, dtype=dtype)
                    for name, (dtype, shape, _) in particle_fields(dimension).items()})

    def __getattr__(self, name):
        arrays = self.__dict__.get("arrays")
        if arrays is not None and name in arrays:
            return arrays[name]
        raise AttributeError(name)

    def __len__(self):
        return len(self.arrays["id"])

    @property
    def n_ghost(self):
        return len(self) - self.n_owned

    def select(self, index, n_owned=None):
        """A new Particles holding the rows ``index`` (all of them owned unless said)."""
        return Particles({name: array[index] for name, array in self.arrays.items()}, n_owned,
                         self.dimension)

    def owned(self):
        """The owned particles alone, without ghosts (its arrays are views of these)."""
        return self.select(slice(0, self.n_owned))

    def owned_copy(self):
        """The owned particles alone, in arrays of their own."""
        return Particles({name: array[:self.n_owned].copy()
                          for name, array in self.arrays.items()}, None, self.dimension)

    @staticmethod
    def concatenate(parts, n_owned=None, dimension=DEFAULT_DIMENSION):
        """The particles of ``parts`` in order (``dimension``: d when there are no parts)."""
        parts = list(parts)
        if not parts:
            return Particles.empty(dimension)
        return Particles({name: np.concatenate([p.arrays[name] for p in parts])
                          for name in FIELDS}, n_owned)

    def sorted_by_id(self):
        """The owned particles in ascending global id (for rank-independent output)."""
        order = np.argsort(self.arrays["id"][:self.n_owned], kind="stable")
        return self.select(order)


def owned_fluid_near(particles, low, high, domain=None):
    """(rows, positions) of the owned fluid and inflow particles within the box [low, high]
    (a body's, grown by a band), their positions taken, along a periodic axis of
    ``domain`` (a :class:`parmps.geometry.domain.Domain`), at the image nearest the box's
    centre: a body across the seam sees the particles on both sides of it as they lie
    around it. ``domain`` None or not periodic: the positions as they are."""
    n = particles.n_owned
    position = particles.position[:n]
    if domain is not None and domain.is_periodic:
        position = domain.near(position, 0.5 * (np.asarray(low) + np.asarray(high)))
    kind = particles.kind[:n]
    rows = np.flatnonzero(((kind == FLUID) | (kind == INFLOW))
                          & np.all((position >= low) & (position <= high), axis=1))
    return rows, position[rows]
