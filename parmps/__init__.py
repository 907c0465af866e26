"""parmps: a parallel MPS fluid solver coupled to volume-preserving mass-spring solids."""

__version__ = "0.1.0"

from parmps.result import open_result  # noqa: E402

__all__ = ["open_result", "__version__"]
