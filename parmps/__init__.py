"""parmps: a parallel MPS fluid solver coupled to volume-preserving mass-spring solids."""

__version__ = "0.1.0"
