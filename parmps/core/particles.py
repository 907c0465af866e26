"""The per-rank particle arrays: owned particles first, then ghosts.

Every rank holds its owned particles in slots [0, n_owned) and copies of
neighbouring ranks' particles (ghosts) after them. Global ids are int64, set when
the scene is built, and never change, so runs on different rank counts can be
compared particle by particle.
"""

import numpy as np

FLUID, WALL, DUMMY, SOLID, INFLOW = 0, 1, 2, 3, 4
KIND_NAMES = {FLUID: "fluid", WALL: "wall", DUMMY: "dummy", SOLID: "solid node",
              INFLOW: "inflow buffer"}

# name -> (dtype, trailing shape, fill value for new particles)
FIELDS = {
    "id": (np.int64, (), -1),
    "kind": (np.int8, (), FLUID),
    "position": (np.float64, (2,), 0.0),
    "velocity": (np.float64, (2,), 0.0),
    "pressure": (np.float64, (), 0.0),
    "number_density": (np.float64, (), 0.0),
    # Solid bodies: index of the body (-1 for none) and of the node within it.
    "body": (np.int32, (), -1),
    "node": (np.int32, (), -1),
}


class Particles:
    """Arrays of FIELDS with the owned particles first; ``n_owned`` marks where ghosts start."""

    def __init__(self, arrays, n_owned=None):
        size = len(arrays["id"])
        self.arrays = {}
        for name, (dtype, shape, fill) in FIELDS.items():
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
    def empty(cls):
        return cls({name: np.empty((0,) + shape, dtype=dtype)
                    for name, (dtype, shape, _) in FIELDS.items()})

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
        return Particles({name: array[index] for name, array in self.arrays.items()}, n_owned)

    def owned(self):
        """The owned particles alone, without ghosts (a copy)."""
        return self.select(slice(0, self.n_owned))

    @staticmethod
    def concatenate(parts, n_owned=None):
        parts = list(parts)
        if not parts:
            return Particles.empty()
        return Particles({name: np.concatenate([p.arrays[name] for p in parts])
                          for name in FIELDS}, n_owned)

    def sorted_by_id(self):
        """The owned particles in ascending global id (for rank-independent output)."""
        order = np.argsort(self.arrays["id"][:self.n_owned], kind="stable")
        return self.select(order)
