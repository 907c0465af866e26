"""Pressure-scheme presets: named sets of case overrides, the one table the studies use.

Each preset is a list of ``SECTION.KEY=VALUE`` overrides (as ``--set`` takes them),
complete against the defaults: each names its source, and a mixed source its measure and
its rows beside bodies (PURE_MIXED: the mixed source there too, as before the default
took the density source beside bodies). "default" is the defaults themselves (the density
source, smooth measure, GC, the extrapolated surface). "MPS" is the original scheme; Khayyer &
Gotoh's HS is the density_rate source, ECS the compensated_rate one, HL the higher_order
Laplacian, GC the corrected gradient; KK is Kondo & Koshizuka's second difference. The
free-surface condition: P = 0 on the free-surface particles, left uncorrected (every
scheme before the extrapolated condition), or P = 0 half a spacing beyond them, with the
corrected gradient applied to them (the default since). docs/schemes.md has the formulas.
"""

DIRICHLET = ['mps.free_surface="dirichlet"']
EXTRAPOLATED = ['mps.free_surface="extrapolated"']
PURE_MIXED = ['mps.mixed.beside_bodies="mixed"']
WITH_N = ['mps.mixed.kernel="mps"']

SCHEMES = {
    "default": [],
    "default, no clamp": ["mps.clamp_negative_pressure=false"],
    # The density source with the original (minimum-pressure) gradient, the rest default.
    "density": ['mps.source="density"', 'mps.gradient="minimum"'],
    "MPS": ['mps.source="density"', 'mps.density.kernel="mps"', 'mps.gradient="minimum"',
            *DIRICHLET],
    "MPS + GC": ['mps.source="density"', 'mps.density.kernel="mps"', 'mps.gradient="corrected"',
                 *DIRICHLET],
    "MPS (smooth n) + GC": ['mps.source="density"', 'mps.density.kernel="smooth"',
                            'mps.gradient="corrected"', *DIRICHLET],
    "mixed": ['mps.source="mixed"', "mps.mixed.relaxation=0.01", *WITH_N, *PURE_MIXED,
              'mps.gradient="minimum"', *DIRICHLET],
    "mixed + GC": ['mps.source="mixed"', "mps.mixed.relaxation=0.01", *WITH_N, *PURE_MIXED,
                   'mps.gradient="corrected"', *DIRICHLET],
    "mixed (γ 0.1) + GC": ['mps.source="mixed"', "mps.mixed.relaxation=0.1", *WITH_N,
                           *PURE_MIXED, 'mps.gradient="corrected"', *DIRICHLET],
    "mixed (γ 0.1, smooth n) + GC": ['mps.source="mixed"', "mps.mixed.relaxation=0.1",
                                     'mps.mixed.kernel="smooth"', *PURE_MIXED,
                                     'mps.gradient="corrected"', *DIRICHLET],
    "HS": ['mps.source="density_rate"', 'mps.gradient="minimum"', *DIRICHLET],
    "HS + HL": ['mps.source="density_rate"', 'mps.laplacian="higher_order"',
                'mps.gradient="minimum"', *DIRICHLET],
    "HS (lattice) + GC": ['mps.source="density_rate"',
                          'mps.density_rate.normalisation="lattice"',
                          'mps.gradient="corrected"', *DIRICHLET],
    "HS + ECS + HL + GC": ['mps.source="compensated_rate"', 'mps.laplacian="higher_order"',
                           'mps.gradient="corrected"', *DIRICHLET],
    "HS + ECS (lattice) + GC": ['mps.source="compensated_rate"',
                                'mps.compensated_rate.normalisation="lattice"',
                                'mps.gradient="corrected"', *DIRICHLET],
    "KK": ['mps.source="density_acceleration"', 'mps.gradient="minimum"', *DIRICHLET],
    "KK + GC": ['mps.source="density_acceleration"', 'mps.gradient="corrected"', *DIRICHLET],
    "MPS (smooth n) + GC, extrapolated surface": ['mps.source="density"',
                                                  'mps.density.kernel="smooth"',
                                                  'mps.gradient="corrected"', *EXTRAPOLATED],
    "mixed (γ 0.1) + GC, extrapolated surface": ['mps.source="mixed"',
                                                 "mps.mixed.relaxation=0.1", *WITH_N,
                                                 *PURE_MIXED, 'mps.gradient="corrected"',
                                                 *EXTRAPOLATED],
    # The mixed source as it stands (γ 0.05, smooth measure, the density source beside
    # bodies), the Lobovsky case's choice.
    "mixed, density beside bodies": ['mps.source="mixed"', 'mps.gradient="corrected"',
                                     *EXTRAPOLATED],
    "MPS (smooth n) + GC, extrapolated surface, shifting": [
        'mps.source="density"', 'mps.density.kernel="smooth"', 'mps.gradient="corrected"',
        *EXTRAPOLATED, 'mps.shifting="fickian"'],
}

# The presets scripts/study.py sweeps (the dam break's front against resolution) and those
# scripts/compare_schemes.py runs on every measurement by default.
STUDIED = ("density", "default", "default, no clamp")
COMPARED = tuple(label for label in SCHEMES if label not in STUDIED)


def overrides(label):
    """The overrides of preset ``label``; an unknown label is a one-line CaseError."""
    from parmps.errors import CaseError
    if label not in SCHEMES:
        raise CaseError(f"no scheme preset '{label}' (known: {', '.join(SCHEMES)})")
    return list(SCHEMES[label])
