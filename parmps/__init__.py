"""parmps: a parallel MPS fluid solver coupled to volume-preserving mass-spring solids."""

__version__ = "0.1.0"

__all__ = ["open_result", "__version__"]


def open_result(path):
    """Open a run's output, ``OUTDIR/result.h5`` or ``OUTDIR``: a
    :class:`parmps.result.Result` giving frames, diagnostics, probes, bodies and checks by
    name as NumPy arrays, read lazily (see :mod:`parmps.result`)."""
    # Imported here: importing the package must not load NumPy (and with it OpenBLAS)
    # before the command line has asked BLAS for one thread per rank.
    from parmps.result import open_result as _open_result
    return _open_result(path)
