"""Reading a run's output: :func:`open_result` gives every dataset by name as NumPy arrays.

A result file (``OUTDIR/result.h5``, docs/design.md §5) holds frames of particles, one row
per step of diagnostics, and series of probes, bodies and checks. This module is the one
reader of that layout: scripts, tests and the validation metrics all go through it.
Nothing is read until it is asked for, and what was read is kept::

    import parmps

    with parmps.open_result("out/hydrostatic") as result:
        last = result.frames[-1]
        print(last.time, last.pressure[last.kind == 0].max())
        print(result.probes["P1"].value.mean(), result.diagnostics["dt"].sum())

Frames are sorted by particle id, whatever the rank count of the run.
"""

import os
from collections.abc import Mapping, Sequence
from functools import cached_property

import numpy as np

from parmps.errors import CaseError

FILE_NAME = "result.h5"
FRAME_FIELDS = ("id", "kind", "position", "velocity", "pressure", "number_density")


def open_result(path):
    """Open a result: ``OUTDIR/result.h5`` or the directory ``OUTDIR`` holding it.

    Returns a :class:`Result`; use it in a ``with`` block (or call ``close()``) to close
    the file. A missing or unreadable file raises :class:`parmps.errors.CaseError` with
    one line naming it.
    """
    return Result(path)


def result_path(path):
    """The result file a path names: the path itself, or ``result.h5`` in that directory."""
    path = os.fspath(path)
    return os.path.join(path, FILE_NAME) if os.path.isdir(path) else path


class Group(Mapping):
    """The datasets of one HDF5 group by name, each read (whole) on first access.

    Names are also attributes (``group.time`` is ``group["time"]``); ``attrs`` holds the
    group's attributes (a probe's ``kind`` and ``units``, a check's ``body``).
    """

    def __init__(self, group):
        self._group = group
        self._cache = {}

    def __getitem__(self, name):
        if name not in self._cache:
            item = self._group[name]
            if not hasattr(item, "shape"):
                raise KeyError(f"{name} is a group, not a dataset")
            self._cache[name] = item[()]
        return self._cache[name]

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self[name]
        except KeyError:
            raise AttributeError(f"no dataset '{name}' (there are: "
                                 f"{', '.join(self)})") from None

    def __iter__(self):
        return (name for name, item in self._group.items() if hasattr(item, "shape"))

    def __len__(self):
        return sum(1 for _ in self)

    @property
    def attrs(self):
        """The group's attributes as a plain dict."""
        return dict(self._group.attrs)

    def __repr__(self):
        return f"<{type(self).__name__} {self._group.name}: {', '.join(self)}>"


class Groups(Mapping):
    """The sub-groups of one HDF5 group (probes, bodies, checks) by name, each a :class:`Group`;
    empty when the run wrote none."""

    def __init__(self, group):
        self._group = group
        self._cache = {}

    def __getitem__(self, name):
        if self._group is None or name not in self._group:
            known = ", ".join(self) or "none"
            raise KeyError(f"no '{name}' in this result (there are: {known})")
        if name not in self._cache:
            self._cache[name] = Group(self._group[name])
        return self._cache[name]

    def __iter__(self):
        if self._group is None:
            return iter(())
        return (name for name, item in self._group.items() if not hasattr(item, "shape"))

    def __len__(self):
        return sum(1 for _ in self)

    def __repr__(self):
        return f"<{type(self).__name__}: {', '.join(self)}>"


class Frame:
    """One frame: ``time``, ``step``, ``dt`` and the particle fields sorted by id, each read on
    first use. ``bodies`` gives the nodes of each body (``position``, ``velocity``)."""

    def __init__(self, group):
        self._group = group
        self._fields = {}
        self.time = float(group.attrs["time"])
        self.step = int(group.attrs["step"])
        self.dt = float(group.attrs["dt"])

    @cached_property
    def _order(self):
        return np.argsort(self._group["id"][()], kind="stable")

    def field(self, name):
        """A particle field by name, sorted by id."""
        if name not in self._fields:
            if name not in self._group or not hasattr(self._group[name], "shape"):
                raise KeyError(f"frame {self.step} has no field '{name}'")
            self._fields[name] = self._group[name][()][self._order]
        return self._fields[name]

    def __getitem__(self, name):
        return self.field(name)

    def __getattr__(self, name):
        if name.startswith("_"):
            raise AttributeError(name)
        try:
            return self.field(name)
        except KeyError as exc:
            raise AttributeError(str(exc)) from None

    @property
    def names(self):
        """The particle fields this frame holds."""
        return [name for name, item in self._group.items() if hasattr(item, "shape")]

    @cached_property
    def bodies(self):
        """Each body's nodes in this frame, by body name (a :class:`Groups`)."""
        return Groups(self._group["solids"] if "solids" in self._group else None)

    def as_dict(self):
        """Every field and ``time``, ``step``, ``dt`` as one dict of arrays."""
        data = {name: self.field(name) for name in self.names}
        data.update(time=self.time, step=self.step, dt=self.dt)
        return data

    def __len__(self):
        return len(self._order)

    def __repr__(self):
        return f"<Frame step {self.step}, t = {self.time:g} s, {len(self)} particles>"


class Frames(Sequence):
    """The frames of a result in time order: index, slice, iterate; ``times`` and ``steps``
    without reading any particle."""

    def __init__(self, group):
        self._group = group
        self._names = sorted(group) if group is not None else []
        self._cache = {}

    def __len__(self):
        return len(self._names)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[k] for k in range(*index.indices(len(self)))]
        name = self._names[index]
        if name not in self._cache:
            self._cache[name] = Frame(self._group[name])
        return self._cache[name]

    @cached_property
    def times(self):
        """Each frame's time [s]."""
        return np.array([self._group[name].attrs["time"] for name in self._names], float)

    @cached_property
    def steps(self):
        """Each frame's step number."""
        return np.array([self._group[name].attrs["step"] for name in self._names], np.int64)

    def at_step(self, step):
        """The frame written at ``step``."""
        name = f"{int(step):08d}"
        if name not in self._names:
            raise KeyError(f"no frame at step {step}")
        return self[self._names.index(name)]

    def nearest(self, time):
        """The frame whose time is closest to ``time``."""
        return self[int(np.argmin(np.abs(self.times - time)))]


class Result:
    """A run's output, read lazily. See :func:`open_result`.

    - ``frames``: the particle frames (:class:`Frames`), ``time``: their times;
    - ``diagnostics``: one row per step (``step``, ``time``, ``dt``, ``ksp_iterations``, ...);
    - ``probes``, ``bodies``, ``checks``: by name, each a :class:`Group` of series
      (a probe's ``time`` and ``value``; a body's ``time``, ``volume_error``,
      ``newton_steps``, ``fluid_force``, ``centroid``, ``springs`` and ``surface`` (its
      boundary facets: loop edges in 2D, outward triangles in 3D); a check's ``time``,
      ``crossings``, ``total``);
    - ``case``: the validated case the run used; ``case_text``: its TOML text;
    - ``complete``: False for a run that stopped before its end.
    """

    def __init__(self, path):
        import h5py
        self.path = result_path(path)
        if not os.path.isfile(self.path):
            raise CaseError(f"{self.path}: no result file there")
        try:
            self._file = h5py.File(self.path, "r")
        except OSError as exc:
            raise CaseError(f"{self.path}: cannot read it as a result ({exc})") from None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Close the file; arrays already read stay valid."""
        self._file.close()

    def _group(self, name):
        return self._file[name] if name in self._file else None

    @cached_property
    def frames(self):
        return Frames(self._group("frames"))

    @property
    def time(self):
        """The frames' times [s]."""
        return self.frames.times

    @cached_property
    def diagnostics(self):
        group = self._group("diagnostics")
        if group is None:
            raise CaseError(f"{self.path}: no diagnostics (the run never took a step)")
        return Group(group)

    @cached_property
    def probes(self):
        return Groups(self._group("probes"))

    @cached_property
    def bodies(self):
        return Groups(self._group("solids"))

    @cached_property
    def checks(self):
        return Groups(self._group("checks"))

    @property
    def attrs(self):
        """The file's attributes (``complete``, ...)."""
        return dict(self._file.attrs)

    @property
    def complete(self):
        return bool(self._file.attrs.get("complete", True))

    @cached_property
    def case_text(self):
        text = self._file["case"].attrs["toml"]
        return text.decode() if isinstance(text, bytes) else str(text)

    @cached_property
    def case(self):
        from parmps import config, schema
        return schema.validate(config.load_text(self.case_text, self.path))

    def __repr__(self):
        return f"<Result {self.path}: {len(self.frames)} frames>"
