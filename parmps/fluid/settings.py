"""Case sections of the fluid: its material, the MPS scheme and the pressure solver."""

from parmps.config import ByDimension, Key, Section
from parmps.errors import CaseError
from parmps.fluid.viscous import VISCOSITY_SCHEMES
from parmps.fluid.schemes import (GRADIENTS, LAPLACIANS, SHIFTINGS, SOURCES, SURFACES,
                                  scheme_class)


def _mps_section():
    keys = {
        "re_number_density": Key("float", 2.3, gt=1.0, le=5.0,
                                 doc="radius for number density and gradient, in l0"),
        # Measured in 3D (docs/performance.md, "The free surface's level, and 2.3 l0 as 3D's
        # default radius"): 2.3 l0 holds 56 neighbours against 3.1's 122 and halves the step's
        # cost; there the still tank meets every target, SPHERIC and the plate as at 3.1.
        "re_laplacian": Key("float", ByDimension(3.1, 2.3), gt=1.0, le=5.0,
                            doc="radius for the Laplacian and the viscous term, in l0"),
        "surface_threshold": Key("float", 0.97, gt=0.0, lt=1.0,
                                 doc="beta: n* < beta n0 marks a free-surface particle"),
        "neighbour_threshold": Key("float", 0.0, ge=0.0, lt=1.0,
                                   doc="also surface if neighbour count < this times the "
                                       "full-lattice count (0 disables)"),
        "source": Key("str", "mixed", choices=tuple(SOURCES),
                      doc="the PPE source scheme (settings in [mps.<name>])"),
        "laplacian": Key("str", "standard", choices=tuple(LAPLACIANS),
                         doc="the PPE's Laplacian (settings in [mps.<name>])"),
        "gradient": Key("str", "corrected", choices=tuple(GRADIENTS),
                        doc="the pressure-gradient scheme (settings in [mps.<name>])"),
        "free_surface": Key("str", "extrapolated", choices=tuple(SURFACES),
                            doc="where P = 0: \"extrapolated\" half a spacing beyond the "
                                "free-surface particles, \"dirichlet\" on them"),
        # In 2D the dynamic stabilisation keeps the dam breaks' energy falling past their
        # first impact and the Lobovsky plateau within its target, where Fickian shifting
        # moves it past (docs/design.md §1.8); the 3D dam break never gained energy.
        "shifting": Key("str", ByDimension("dynamic_stabilisation", "none"),
                        choices=tuple(SHIFTINGS),
                        doc="particle regularisation after the correction: \"none\", "
                            "\"fickian\" shifting or \"dynamic_stabilisation\" "
                            "(settings in [mps.<name>])"),
        # docs/design.md, "Implicit viscosity": auto keeps the explicit term wherever the
        # viscous limit does not bind, so every run that ran before runs as it did.
        "viscosity_scheme": Key("str", "auto", choices=VISCOSITY_SCHEMES,
                                doc="the viscous term: \"auto\" backward Euler where the "
                                    "viscous limit (time.viscous_number) would bind the step, "
                                    "explicit otherwise; \"explicit\" always (the step then "
                                    "kept within the viscous limit); \"implicit\" always"),
        "compressibility": Key("float", 0.45e-9, ge=0.0, doc="c_comp [1/Pa]"),
        "clamp_negative_pressure": Key("bool", True,
                                       doc="negative pressures are set to 0 after the solve"),
        "collision": Key("bool", True,
                         doc="the collision model: pairs closer than collision_distance "
                             "bounce apart"),
        "collision_distance": Key("float", 0.5, gt=0.0, lt=1.0, doc="in l0"),
        "restitution": Key("float", 0.2, ge=0.0, le=1.0,
                           doc="coefficient of restitution of the collision model"),
    }
    for choice, registry in (("source", SOURCES), ("laplacian", LAPLACIANS),
                             ("gradient", GRADIENTS), ("free_surface", SURFACES),
                             ("shifting", SHIFTINGS)):
        for name in registry:
            scheme = scheme_class(registry, name)
            keys[name] = Key("table", keys=scheme.KEYS,
                             doc=f"settings of mps.{choice} = \"{name}\"" +
                                 (f": {scheme.__doc__}" if scheme.__doc__ else ""))
    replaced = {
        "relaxation": "the density source's gamma is [mps.density] relaxation",
        "source_term": "choose the source with mps.source (\"density\", \"mixed\", ...)",
        "mixed_relaxation": "the mixed source's gamma is [mps.mixed] relaxation",
        "gradient_correction": "choose the gradient with mps.gradient = \"corrected\"",
        "gradient_correction_limit": "the corrected gradient's limit is "
                                     "[mps.corrected] eigenvalue_limit",
    }
    return Section(keys, replaced=replaced)


SECTIONS = {
    "fluid": Section({
        "density": Key("float", 1000.0, gt=0.0, doc="rho [kg/m^3]"),
        "viscosity": Key("float", 1.0e-6, ge=0.0, doc="kinematic viscosity nu [m^2/s]"),
    }),
    "mps": _mps_section(),
    "pressure": Section({
        "rtol": Key("float", 1.0e-6, gt=0.0, lt=1.0,
                    doc="CG stops at this residual relative to the right-hand side"),
        "max_iterations": Key("int", 1000, gt=0,
                              doc="most CG iterations of one solve (reaching it: the solve "
                                  "failed)"),
        "reuse_preconditioner": Key("int", 50, ge=0,
                                    doc="most steps a preconditioner set-up is reused for "
                                        "(0: set up every step)"),
        "setup_cost": Key("float", 40.0, ge=0.0,
                          doc="what a preconditioner set-up costs, in CG iterations: it is "
                              "set up again once a step's iterations exceed the average "
                              "cost per step since the last set-up"),
        "ksp_type": Key("str", "cg", doc="PETSc Krylov method (-pressure_ksp_type)"),
        "pc_type": Key("str", "gamg", doc="PETSc preconditioner (-pressure_pc_type)"),
        "options": Key("options", {}, doc="more PETSc options, without the pressure_ prefix"),
    }),
    # The implicit viscosity's system (parmps.fluid.viscous): diagonally dominant, so CG with
    # the diagonal is enough (docs/design.md, "Implicit viscosity").
    "viscous": Section({
        "rtol": Key("float", 1.0e-8, gt=0.0, lt=1.0,
                    doc="CG stops at this residual relative to the right-hand side (each "
                        "velocity component's system)"),
        "max_iterations": Key("int", 1000, gt=0,
                              doc="most CG iterations of one component's solve (reaching it: "
                                  "the solve failed)"),
        "ksp_type": Key("str", "cg", doc="PETSc Krylov method (-viscous_ksp_type)"),
        "pc_type": Key("str", "jacobi", doc="PETSc preconditioner (-viscous_pc_type)"),
        "options": Key("options", {}, doc="more PETSc options, without the viscous_ prefix"),
    }),
}


def check(case):
    mps = case["mps"]
    if mps["re_laplacian"] < mps["re_number_density"]:
        raise CaseError(f"mps.re_laplacian ({mps['re_laplacian']}) must be >= "
                        f"mps.re_number_density ({mps['re_number_density']})")
