"""Solid models behind one interface (:class:`parmps.solids.model.SolidModel`).

``MODELS`` is the one place a solid model is registered: its name, as the case
chooses it with ``[solid] model``, and where its class lives. Importing this
package loads no model; :func:`solid_model` builds the case's.
"""

from parmps import registry

MODELS = {
    "mass_spring": "parmps.solids.mass_spring.model:MassSpringModel",
}


def solid_model(case):
    """The case's solid model with every body built, or None for a case without bodies."""
    if not case.get("body"):
        return None
    return registry.load(MODELS, case["solid"]["model"]).from_case(case)
