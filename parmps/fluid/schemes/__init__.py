"""Pressure schemes: the PPE's right-hand side (a source), its matrix (a Laplacian), the gradient.

This registry is the one place a scheme is registered: a name, and where its
class lives. A source scheme supplies ``rhs(step)``, the right-hand side of every
unknown PPE row; a Laplacian scheme supplies ``rows(...)``, the PPE's matrix
rows; a gradient scheme supplies ``gradient(...)``, the pressure gradient that
moves the fluid and pushes the bodies (the coupling takes the same one). Each
class declares ``KEYS``, the settings of its own table ``[mps.<name>]`` in the
case; the case chooses one of each with ``mps.source``, ``mps.laplacian`` and
``mps.gradient``; a shifting scheme (``mps.shifting``) supplies ``shift(...)``, a
small move of the fluid particles after the correction that keeps them ordered.
The exact form of each scheme, with its source, is in
docs/design.md §1.4 and docs/schemes.md. Khayyer & Gotoh's names: HS is
``density_rate``, HS + ECS ``compensated_rate``, HL the ``higher_order``
Laplacian, GC the ``corrected`` gradient; Kondo & Koshizuka's second time
difference is ``density_acceleration``.
"""

from parmps.registry import load

SOURCES = {
    "density": "parmps.fluid.schemes.density:DensitySource",
    "mixed": "parmps.fluid.schemes.mixed:MixedSource",
    "density_rate": "parmps.fluid.schemes.rate:DensityRateSource",
    "compensated_rate": "parmps.fluid.schemes.rate:CompensatedRateSource",
    "density_acceleration": "parmps.fluid.schemes.kondo_koshizuka:DensityAccelerationSource",
}

LAPLACIANS = {
    "standard": "parmps.fluid.schemes.laplacian:StandardLaplacian",
    "higher_order": "parmps.fluid.schemes.laplacian:HigherOrderLaplacian",
}

GRADIENTS = {
    "minimum": "parmps.fluid.schemes.gradient:MinimumPressureGradient",
    "corrected": "parmps.fluid.schemes.gradient:CorrectedGradient",
}

SURFACES = {
    "dirichlet": "parmps.fluid.schemes.surface:DirichletSurface",
    "extrapolated": "parmps.fluid.schemes.surface:ExtrapolatedSurface",
}

SHIFTINGS = {
    "none": "parmps.fluid.schemes.shifting:NoShifting",
    "fickian": "parmps.fluid.schemes.shifting:FickianShifting",
    "dynamic_stabilisation": "parmps.fluid.schemes.shifting:DynamicStabilisation",
}


def scheme_class(registry, name):
    """The class registered under ``name`` in ``registry`` (SOURCES, LAPLACIANS, GRADIENTS,
    SURFACES or SHIFTINGS)."""
    return load(registry, name)


def registered():
    """Every registered scheme as (name, class): sources, Laplacians, gradients, surfaces,
    shiftings."""
    return [(name, scheme_class(registry, name))
            for registry in (SOURCES, LAPLACIANS, GRADIENTS, SURFACES, SHIFTINGS)
            for name in registry]
