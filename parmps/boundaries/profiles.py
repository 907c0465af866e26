"""Inflow profiles across an opening: each lane's speed over the mean, before scaling.

``shape(points, centre, widths, circle_radius)`` returns the fully developed laminar
profile at ``points`` (n, d - 1) across the flow, in units of its own mean over the
opening (the continuous mean, so 1 on average over the exact cross-section):

- 2D, a channel of width h: ``1.5 (1 - (2 r / h)^2)``.
- 3D, a rectangular duct of widths 2a x 2b: the exact series of the Poisson problem
  (White, Viscous Fluid Flow, eq. 3-48), with y across 2a, z across 2b from the centre,
  ``f = sum_{n odd} (-1)^((n-1)/2) n^-3 [1 - cosh(n pi z / 2a) / cosh(n pi b / 2a)]
  cos(n pi y / 2a)``, over its mean ``sum_{n odd} 2 / (pi n^4) [1 - (2a / (n pi b))
  tanh(n pi b / 2a)]``. Alternating in n with terms below n^-3: :data:`DUCT_TERMS` odd
  terms leave under 1e-10 of the centre-line value.
- 3D, a circle of radius R (a pipe): ``2 (1 - (r / R)^2)``.

The inlet then scales the lanes so the delivered flow rate is exactly the requested
mean times the opening's area (parmps.boundaries.open).
"""

import numpy as np

DUCT_TERMS = 2000
CHUNK = 256


def _cosh_ratio(x, big):
    """cosh(x) / cosh(big) for |x| <= big, without overflow."""
    x = np.abs(x)
    return np.exp(x - big) * (1.0 + np.exp(-2.0 * x)) / (1.0 + np.exp(-2.0 * big))


def duct(y, z, a, b):
    """The rectangular duct's profile over its mean at (y, z) from the centre, half-widths
    a (along y) and b (along z)."""
    n = 2.0 * np.arange(DUCT_TERMS) + 1.0
    sign = np.where(np.arange(DUCT_TERMS) % 2 == 0, 1.0, -1.0)
    k = n * np.pi / (2.0 * a)
    mean = np.sum(2.0 / (np.pi * n ** 4) * (1.0 - np.tanh(k * b) / (k * b)))
    y, z = np.atleast_1d(y), np.atleast_1d(z)
    value = np.empty(len(y))
    # In chunks of points: a (points x terms) array of a fine duct's cross-section would
    # take gigabytes at once.
    for start in range(0, len(y), CHUNK):
        part = slice(start, start + CHUNK)
        terms = (sign / n ** 3)[None, :] * (1.0 - _cosh_ratio(np.outer(z[part], k), k * b)) \
            * np.cos(np.outer(y[part], k))
        value[part] = terms.sum(axis=1)
    return value / mean


def parabolic(points, centre, widths, radius=None):
    """The fully developed profile over its mean at ``points`` across the flow (see the
    module docstring): a circle of ``radius`` about ``centre`` if given, else the box of
    ``widths`` about it."""
    offset = np.asarray(points, dtype=float) - np.asarray(centre, dtype=float)
    if radius is not None:
        return 2.0 * (1.0 - np.sum(offset ** 2, axis=1) / radius ** 2)
    if offset.shape[1] == 1:
        return 1.5 * (1.0 - (2.0 * offset[:, 0] / widths[0]) ** 2)
    return duct(offset[:, 0], offset[:, 1], 0.5 * widths[0], 0.5 * widths[1])
