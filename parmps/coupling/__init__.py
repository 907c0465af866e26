"""Fluid-solid coupling schemes.

``SCHEMES`` is the one place a coupling scheme is registered, by the name the
case chooses with ``[coupling] scheme``. A scheme is a participant of the fluid
step (see :class:`parmps.run.steppers.FluidStepper`) that owns the exchange of
forces and node states between the fluid and the solid model.
"""

from parmps import registry

SCHEMES = {
    "weak": "parmps.coupling.weak:WeakCoupling",
    "implicit_pressure": "parmps.coupling.implicit_pressure:ImplicitPressureCoupling",
}


def coupling_scheme(case, model, comm, fluid):
    """The case's coupling scheme for ``model`` (a SolidModel) and ``fluid`` (its solver)."""
    return registry.load(SCHEMES, case["coupling"]["scheme"])(model, comm, fluid)
