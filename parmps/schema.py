"""The case schema: every component's sections and checks, assembled in one place.

Each component declares the sections it reads and the checks that span them in
its own ``settings`` module (``SECTIONS``, ``check(case)``); this module lists
the components, and :func:`validate` runs the generic machinery of
:mod:`parmps.config` over all of them. The validated case is a plain nested dict
with every default filled in, plus ``dimension``.
"""

from parmps import config
from parmps.boundaries import settings as boundaries
from parmps.checks import settings as checks
from parmps.core import settings as core
from parmps.coupling import settings as coupling
from parmps.fluid import settings as fluid
from parmps.geometry import settings as geometry
from parmps.io import settings as io
from parmps.parallel import settings as parallel
from parmps.probes import settings as probes
from parmps.run import settings as run
from parmps.solids import settings as solids

# Checks run in this order, each after every section is validated.
COMPONENTS = (core, geometry, fluid, run, boundaries, solids, coupling, parallel, io, probes,
              checks)

SECTIONS = {name: section for component in COMPONENTS
            for name, section in component.SECTIONS.items()}


def validate(raw):
    """Check a parsed case (a dict) against every component; returns it with defaults."""
    dimension = core.check_dimension(raw) if isinstance(raw, dict) else 2
    case = config.validate_sections(raw, SECTIONS, dimension)
    case["dimension"] = dimension
    for component in COMPONENTS:
        component.check(case)
    return case
