"""Pressure schemes: the PPE's right-hand side (a source) and the pressure gradient.

This registry is the one place a scheme is registered: a name, and where its
class lives. A source scheme supplies ``rhs(step)``, the right-hand side of every
unknown PPE row; a gradient scheme supplies ``gradient(...)``, the pressure
gradient that moves the fluid and pushes the bodies (the coupling takes the same
one). Each class declares ``KEYS``, the settings of its own table ``[mps.<name>]``
in the case; the case chooses one of each with ``mps.source`` and
``mps.gradient``. The exact form of each scheme, with its source, is in
docs/design.md.
"""

import importlib

SOURCES = {
    "density": "parmps.fluid.schemes.density:DensitySource",
    "mixed": "parmps.fluid.schemes.mixed:MixedSource",
}

GRADIENTS = {
    "minimum": "parmps.fluid.schemes.gradient:MinimumPressureGradient",
    "corrected": "parmps.fluid.schemes.gradient:CorrectedGradient",
}


def scheme_class(registry, name):
    """The class registered under ``name`` in ``registry`` (SOURCES or GRADIENTS)."""
    module, attribute = registry[name].split(":")
    return getattr(importlib.import_module(module), attribute)


def registered():
    """Every registered scheme as (name, class), sources first."""
    return [(name, scheme_class(registry, name))
            for registry in (SOURCES, GRADIENTS) for name in registry]
