"""Reference values of the full lattice, against sums written out shell by shell."""

import numpy as np
import pytest

from parmps.core import lattice

SPACING = 0.01

# Shells of the lattice around a particle: squared distance in units of l0^2 ->
# how many lattice points lie at that distance.
#   2D: 1 (±1,0): 4; 2 (±1,±1): 4; 4 (±2,0): 4; 5 (±2,±1): 8; 8 (±2,±2): 4; 9 (±3,0): 4.
SHELLS_2D = {1: 4, 2: 4, 4: 4, 5: 8, 8: 4, 9: 4}
#   3D: 1 (±1,0,0): 6; 2 (±1,±1,0): 3 planes x 4 = 12; 3 (±1,±1,±1): 8; 4 (±2,0,0): 6;
#       5 (±2,±1,0): 6 orderings x 4 signs = 24; 6 (±2,±1,±1): 3 x 8 = 24;
#       8 (±2,±2,0): 3 x 4 = 12; 9 (±3,0,0): 6 and (±2,±2,±1): 3 x 8 = 24, so 30.
SHELLS_3D = {1: 6, 2: 12, 3: 8, 4: 6, 5: 24, 6: 24, 8: 12, 9: 30}


def hand(shells, re):
    """n0, lambda0 / l0^2 and the neighbour count from shells, for re in units of l0."""
    inside = {r2: m for r2, m in shells.items() if np.sqrt(r2) < re}
    n0 = sum(m * (re / np.sqrt(r2) - 1.0) for r2, m in inside.items())
    moment = sum(m * (re / np.sqrt(r2) - 1.0) * r2 for r2, m in inside.items())
    return n0, moment / n0, sum(inside.values())


@pytest.mark.parametrize("dimension, shells", [(2, SHELLS_2D), (3, SHELLS_3D)])
@pytest.mark.parametrize("re", [1.5, 2.1, 3.1])
def test_reference_values_match_shells(dimension, shells, re):
    n0_hand, lambda_hand, count_hand = hand(shells, re)
    n0, lambda0 = lattice.reference_values(SPACING, re * SPACING, dimension)
    assert n0 == pytest.approx(n0_hand, rel=1e-13)
    assert lambda0 == pytest.approx(lambda_hand * SPACING ** 2, rel=1e-13)
    assert lattice.neighbour_count_reference(SPACING, re * SPACING, dimension) == count_hand


def test_re_2_1_written_out():
    # 2D, re = 2.1 l0: 4 neighbours at l0 (w = 1.1), 4 at sqrt2 l0, 4 at 2 l0.
    w1, w2, w4 = 2.1 - 1, 2.1 / np.sqrt(2) - 1, 2.1 / 2 - 1
    n0, lambda0 = lattice.reference_values(SPACING, 2.1 * SPACING, 2)
    assert n0 == pytest.approx(4 * (w1 + w2 + w4), rel=1e-14)
    assert lambda0 == pytest.approx(4 * (w1 + 2 * w2 + 4 * w4) * SPACING ** 2 / n0, rel=1e-14)
    assert lattice.neighbour_count_reference(SPACING, 2.1 * SPACING, 2) == 12
    # 3D, re = 2.1 l0: 6 at l0, 12 at sqrt2 l0, 8 at sqrt3 l0, 6 at 2 l0 (sqrt5 > 2.1).
    w3 = 2.1 / np.sqrt(3) - 1
    n0, lambda0 = lattice.reference_values(SPACING, 2.1 * SPACING, 3)
    assert n0 == pytest.approx(6 * w1 + 12 * w2 + 8 * w3 + 6 * w4, rel=1e-14)
    assert lambda0 == pytest.approx((6 * w1 + 24 * w2 + 24 * w3 + 24 * w4) * SPACING ** 2 / n0,
                                    rel=1e-14)
    assert lattice.neighbour_count_reference(SPACING, 2.1 * SPACING, 3) == 32


def test_values_scale_with_spacing():
    # n0 depends on re / l0 only; lambda0 goes as l0^2.
    for dimension in (2, 3):
        n0, lambda0 = lattice.reference_values(1.0, 3.1, dimension)
        n0_s, lambda0_s = lattice.reference_values(SPACING, 3.1 * SPACING, dimension)
        assert n0_s == pytest.approx(n0, rel=1e-13)
        assert lambda0_s == pytest.approx(lambda0 * SPACING ** 2, rel=1e-13)


def test_one_dimension_and_bad_dimension():
    # 1D, re = 2.1: neighbours at ±1 and ±2.
    n0, _ = lattice.reference_values(1.0, 2.1, 1)
    assert n0 == pytest.approx(2 * (1.1 + 0.05), rel=1e-14)
    with pytest.raises(ValueError):
        lattice.reference_values(1.0, 2.1, 0)
