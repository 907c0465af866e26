"""Prescribed functions of time: an inlet's mean velocity, a time-varying body force.

Each has ``value(t)``, ``integral(t)`` (from 0 to t, exact, so an inlet's particles sit
where the prescribed flow has carried them and a step's impulse is the exact one) and
``peak(t0, t1)`` (the largest magnitude over [t0, t1], for the Courant limit).

- :class:`Constant` ``U``.
- :class:`Ramp` ``U (1 - cos(pi t / T)) / 2`` for t < T, then U: Turek & Hron's start,
  smooth (zero slope) at both ends of the ramp.
- :class:`Table` a piecewise-linear interpolation of rows (t_i, v_i), held constant
  before the first row and after the last; its integral is exact for that interpolant.
- :class:`Oscillation` the vector ``g0 + A cos(2 pi f t)`` (a pulsatile pipe's driving).
"""

import math
import os

import numpy as np

from parmps.errors import CaseError


class Constant:
    def __init__(self, value):
        self.level = float(value)

    def value(self, t):
        return self.level

    def integral(self, t):
        return self.level * t

    def peak(self, t0, t1):
        return abs(self.level)


class Ramp:
    """``U (1 - cos(pi t / T)) / 2`` for 0 <= t < T, U after (0 before 0)."""

    def __init__(self, level, duration):
        self.level = float(level)
        self.duration = float(duration)

    def value(self, t):
        if t <= 0.0:
            return 0.0
        if t >= self.duration:
            return self.level
        return 0.5 * self.level * (1.0 - math.cos(math.pi * t / self.duration))

    def integral(self, t):
        T = self.duration
        if t <= 0.0:
            return 0.0
        if t >= T:
            return self.level * (t - 0.5 * T)
        return 0.5 * self.level * (t - T / math.pi * math.sin(math.pi * t / T))

    def peak(self, t0, t1):
        # Monotonic: the largest value is at the end of the interval.
        return abs(self.value(t1))


class Table:
    """Piecewise-linear through the rows (t_i, v_i) (t strictly increasing, >= 2 rows),
    constant past either end."""

    def __init__(self, times, values):
        self.times = np.asarray(times, dtype=float)
        self.values = np.asarray(values, dtype=float)
        # The antiderivative at the rows, from the first row (trapezoids are exact for
        # a linear interpolant); F(0) is subtracted so that integral(0) = 0.
        widths = np.diff(self.times)
        self.at_rows = np.concatenate(
            [[0.0], np.cumsum(0.5 * widths * (self.values[1:] + self.values[:-1]))])
        self.origin = self._antiderivative(0.0)

    def value(self, t):
        return float(np.interp(t, self.times, self.values))

    def _antiderivative(self, t):
        times, values = self.times, self.values
        if t <= times[0]:
            return values[0] * (t - times[0])
        if t >= times[-1]:
            return self.at_rows[-1] + values[-1] * (t - times[-1])
        i = int(np.searchsorted(times, t, side="right")) - 1
        h = t - times[i]
        slope = (values[i + 1] - values[i]) / (times[i + 1] - times[i])
        return self.at_rows[i] + values[i] * h + 0.5 * slope * h * h

    def integral(self, t):
        return self._antiderivative(t) - self.origin

    def peak(self, t0, t1):
        inside = self.values[(self.times > t0) & (self.times < t1)]
        return float(max(abs(self.value(t0)), abs(self.value(t1)),
                         *np.abs(inside)))


class Oscillation:
    """The vector ``steady + amplitude cos(2 pi frequency t)``."""

    def __init__(self, steady, amplitude=None, frequency=0.0):
        self.steady = np.asarray(steady, dtype=float)
        self.amplitude = (np.zeros_like(self.steady) if amplitude is None
                          else np.asarray(amplitude, dtype=float))
        self.omega = 2.0 * math.pi * float(frequency)
        self.varies = bool(self.omega > 0.0 and np.any(self.amplitude != 0.0))

    def value(self, t):
        if not self.varies:
            return self.steady.copy()
        return self.steady + self.amplitude * math.cos(self.omega * t)

    def integral(self, t):
        if not self.varies:
            return self.steady * t
        return self.steady * t + self.amplitude * math.sin(self.omega * t) / self.omega

    def mean(self, t0, t1):
        """The mean over [t0, t1]: the exact impulse of a step of length t1 - t0, over it."""
        if not self.varies or t1 <= t0:
            return self.value(t0)
        return (self.integral(t1) - self.integral(t0)) / (t1 - t0)


def read_table(path, name, columns=2):
    """The rows of a numeric text table: whitespace- or comma-separated, ``#`` comments and
    blank lines skipped, ``columns`` numbers a row, the first column strictly increasing
    (a time), at least two rows. Returns an array (rows, columns); a bad file is a
    one-line CaseError naming the key ``name``."""
    if not os.path.isfile(path):
        raise CaseError(f"{name}: no such file {path!r} (a relative path is from the case "
                        f"file's directory)")
    rows = []
    with open(path, encoding="utf-8", errors="replace") as handle:
        for number, line in enumerate(handle, 1):
            fields = line.split("#", 1)[0].replace(",", " ").split()
            if not fields:
                continue
            if len(fields) != columns:
                raise CaseError(f"{name}: {path} line {number} has {len(fields)} columns, "
                                f"expected {columns}")
            try:
                row = [float(field) for field in fields]
            except ValueError:
                raise CaseError(f"{name}: {path} line {number} is not {columns} numbers: "
                                f"{line.strip()!r}") from None
            if not all(math.isfinite(v) for v in row):
                raise CaseError(f"{name}: {path} line {number} has a value that is not "
                                f"finite")
            rows.append(row)
    if len(rows) < 2:
        raise CaseError(f"{name}: {path} has {len(rows)} row(s); a table needs at least 2")
    table = np.array(rows)
    steps = np.diff(table[:, 0])
    if np.any(steps <= 0.0):
        bad = int(np.flatnonzero(steps <= 0.0)[0])
        raise CaseError(f"{name}: {path}: the times must increase, but row {bad + 2} "
                        f"(t = {table[bad + 1, 0]:g}) follows t = {table[bad, 0]:g}")
    return table
