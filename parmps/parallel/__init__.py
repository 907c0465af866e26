"""Parallel machinery: the domain decomposition, its settings, MPI helpers.

``DECOMPOSITIONS`` is the one place a decomposition is registered: a name (the
case's ``parallel.decomposition``) and where its class lives. Every class
implements :class:`parmps.parallel.base.Decomposition`; code outside this
package gets its decomposition from :func:`create_decomposition` and never
names one.
"""

from parmps import registry

DECOMPOSITIONS = {
    "slabs": "parmps.parallel.slabs:SlabDecomposition",
    "blocks": "parmps.parallel.blocks:BlockDecomposition",
}

#: what ``parallel.decomposition`` may say: a registered name, or "auto"
CHOICES = ("auto",) + tuple(DECOMPOSITIONS)


def decomposition_class(name):
    """The class registered under ``name``."""
    return registry.load(DECOMPOSITIONS, name)


def create_decomposition(comm, case, name=None):
    """The case's decomposition on ``comm`` (collective), or the one registered as
    ``name``; "auto" chooses with :func:`choose_decomposition`. The one place the case's
    domain, halo and ``[parallel]`` settings are read for it: the decomposition is given
    them as objects. Which one runs, and why, is logged once the scene is distributed
    (:meth:`Decomposition.log_choice`): a case refused while its scene is built gets its
    one line of error alone."""
    from parmps.geometry.domain import Domain
    from parmps.parallel.base import balance_settings, halo_widths
    parallel = case["parallel"]
    why = "parallel.decomposition" if name is None else "asked for"
    name = name or parallel.get("decomposition", "auto")
    if name == "auto" and parallel.get("grid"):
        name, why = "blocks", "auto: parallel.grid is set"
    elif name == "auto":
        name, reason = choose_decomposition(comm.size, case)
        why = f"auto: {reason}"
    domain, halo = Domain.from_case(case), halo_widths(case)
    if domain.is_periodic:
        domain.check_lattice(case["particles"]["spacing"], case["particles"]["origin"],
                             halo.width)
    cls = decomposition_class(name)
    options = {key: parallel.get(key) for key in cls.options}
    decomposition = cls(comm, domain, halo, balance_settings(parallel), **options)
    decomposition.choice = (name, why)
    return decomposition


# Blocks exchange with up to 3^d - 1 neighbours where slabs talk to two: they are
# chosen only when they save at least this fraction of the slabs' modelled ghosts.
_BLOCKS_SAVING = 0.25


def choose_decomposition(ranks, case):
    """(name, reason) of the decomposition "auto" picks for ``ranks`` ranks.

    Slabs exchange with two neighbours, the fewest messages, and are the default.
    Blocks run when slabs do not fit the halo, or when the rank grid with the
    fewest modelled ghosts for the domain's extent (:func:`parmps.parallel.grid.
    choose_grid`) cuts more than one axis and saves at least a quarter of the
    slabs' ghosts. When no grid fits the halo, blocks refuse in their own words.
    """
    from parmps.parallel.base import halo_widths
    from parmps.parallel.grid import capacities, choose_grid, describe_grid, ghost_ratio
    if ranks == 1:
        return "slabs", "one rank"
    lower, upper = case["domain"]["lower"], case["domain"]["upper"]
    _, _, width, min_width = halo_widths(case)
    grid = choose_grid(ranks, lower, upper, min_width, width)
    if grid is None:
        return "blocks", f"no grid of {ranks} ranks fits the halo"
    slab_capacity = int(capacities(lower, upper, min_width)[0])
    if ranks > slab_capacity:
        return "blocks", (f"a {describe_grid(grid)} grid; the domain holds at most "
                          f"{slab_capacity} slabs along x")
    slabs = ghost_ratio((ranks,) + (1,) * (len(lower) - 1), lower, upper, width)
    blocks = ghost_ratio(grid, lower, upper, width)
    compared = (f"modelled ghosts per owned particle: slabs {slabs:.0%}, a "
                f"{describe_grid(grid)} grid {blocks:.0%}")
    if sum(g > 1 for g in grid) > 1 and blocks <= (1 - _BLOCKS_SAVING) * slabs:
        return "blocks", compared
    return "slabs", compared
