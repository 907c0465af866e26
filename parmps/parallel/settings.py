"""Case section of the decomposition: halo, load balance, migration."""

from parmps.config import Key, Section
from parmps.errors import CaseError
from parmps.parallel import CHOICES

SECTIONS = {
    "parallel": Section({
        "decomposition": Key("str", "auto", choices=CHOICES,
                             doc="how the domain is cut over the ranks (parmps.parallel."
                                 "DECOMPOSITIONS): slabs along x, blocks of a px x py (x pz) "
                                 "rank grid, or auto: slabs unless they do not fit the halo or "
                                 "a grid cutting two or more axes models a quarter fewer "
                                 "ghosts (rank 0 logs the choice and why)"),
        "grid": Key("ints", [], gt=0,
                    doc="blocks: the rank grid [px, py] ([px, py, pz] in 3D), whose product "
                        "is the rank count; empty: the grid with the fewest ghosts for the "
                        "domain"),
        "halo_skin": Key("float", 0.6, ge=0.0, le=5.0,
                         doc="extra halo width and neighbour-list skin, in l0"),
        "rebalance_interval": Key("int", 20, gt=0, doc="steps between load-balance checks"),
        "imbalance_tolerance": Key("float", 1.10, gt=1.0,
                                   doc="rebalance when max/mean particles exceeds this"),
        # A wall particle has a pressure row but moves not; a dummy only fills the
        # walls' neighbourhoods. Measured on the SPHERIC tank (half its particles walls
        # and dummies) per phase on 1 and 2 ranks: a wall costs 0.65 of a fluid
        # particle outside the solve and as much in it, a dummy next to nothing.
        "wall_weight": Key("float", 0.8, ge=0.0, le=1.0,
                           doc="load balance: a wall particle's work relative to a fluid "
                               "particle's (a dry wall, away from the water, weighs as a "
                               "dummy)"),
        "dummy_weight": Key("float", 0.1, ge=0.0, le=1.0,
                            doc="load balance: a dummy particle's work relative to a fluid "
                                "particle's"),
        # A body's substeps run on its owner rank while the others wait for its state;
        # measured on the solid-cost scene (bench --solid-cost: a 10,648-node lattice,
        # 46 substeps a step) against its fluid's work per particle weight on 1 rank.
        "node_substep_weight": Key("float", 0.01, ge=0.0,
                                   doc="load balance: one body node's substep relative to a "
                                       "fluid particle's step (a body's substeps count on the "
                                       "rank that runs them; 0: not counted)"),
        "migration_margin": Key("float", 0.5, ge=0.0, le=5.0,
                                doc="particles migrate once one is this far (in l0) outside "
                                    "its region; halo and regions widen by it (0: every step)"),
    }),
}


def check(case):
    grid = case["parallel"]["grid"]
    if grid and len(grid) != len(case["domain"]["lower"]):
        raise CaseError(f"parallel.grid has {len(grid)} entries for a "
                        f"{len(case['domain']['lower'])}D domain: give one per axis")
