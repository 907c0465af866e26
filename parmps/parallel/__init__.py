"""Parallel machinery: the domain decomposition, its settings, MPI helpers.

``DECOMPOSITIONS`` is the one place a decomposition is registered: a name (the
case's ``parallel.decomposition``) and where its class lives. Every class
implements :class:`parmps.parallel.base.Decomposition`; code outside this
package gets its decomposition from :func:`create_decomposition` and never
names one.
"""

import importlib
import logging

log = logging.getLogger(__name__)

DECOMPOSITIONS = {
    "slabs": "parmps.parallel.slabs:SlabDecomposition",
}

#: what ``parallel.decomposition`` may say: a registered name, or "auto"
CHOICES = ("auto",) + tuple(DECOMPOSITIONS)


def decomposition_class(name):
    """The class registered under ``name``."""
    module, attribute = DECOMPOSITIONS[name].split(":")
    return getattr(importlib.import_module(module), attribute)


def create_decomposition(comm, case):
    """The case's decomposition on ``comm`` (collective); "auto" chooses with
    :func:`choose_decomposition` and logs why."""
    name = case["parallel"].get("decomposition", "auto")
    if name == "auto":
        name, why = choose_decomposition(comm.size, case)
        if comm.rank == 0:
            log.info("decomposition: %s (auto: %s)", name, why)
    return decomposition_class(name)(comm, case)


def choose_decomposition(ranks, case):
    """(name, reason) of the decomposition "auto" picks for ``ranks`` ranks."""
    return "slabs", "the only one registered"
