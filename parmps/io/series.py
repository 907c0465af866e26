"""Growing one-dimensional series in result.h5: diagnostics and per-body time series.

Rows are queued in memory (the same values on every rank) and appended on
:meth:`Series.flush`, a collective resize after which rank 0 writes the rows.
"""

import numpy as np


class Series:
    """Named columns under one HDF5 group, each ``(rows,) + shape`` of its dtype."""

    def __init__(self, group, columns):
        """``columns``: name -> (dtype, trailing shape)."""
        self.group = group
        self.columns = dict(columns)
        self.datasets = {}
        for name, (dtype, shape) in self.columns.items():
            if name in group:  # a continued run (see truncate)
                self.datasets[name] = group[name]
                continue
            self.datasets[name] = group.create_dataset(
                name, shape=(0,) + shape, maxshape=(None,) + shape, chunks=(1024,) + shape,
                dtype=dtype)
        self.pending = {name: [] for name in self.columns}
        self.rows = 0

    def add(self, values):
        """Queue one row; a column without a value gets NaN."""
        for name in self.columns:
            self.pending[name].append(values.get(name, np.nan))

    def truncate(self, rows):
        """Keep the first ``rows`` rows (collective): a continued run drops the rows an
        interrupted run wrote after its checkpoint before appending its own."""
        for name, dataset in self.datasets.items():
            dataset.resize((rows,) + dataset.shape[1:])
            self.pending[name] = []
        self.rows = rows

    def flush(self, rank):
        count = len(next(iter(self.pending.values()))) if self.pending else 0
        if count == 0:
            return
        for name, dataset in self.datasets.items():
            dataset.resize((self.rows + count,) + dataset.shape[1:])
            if rank == 0:
                dataset[self.rows:] = np.asarray(self.pending[name], dtype=dataset.dtype)
            self.pending[name] = []
        self.rows += count
