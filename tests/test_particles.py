"""Particle arrays shaped by the dimension d."""

import numpy as np
import pytest

from parmps.core.particles import FIELDS, FLUID, Particles, particle_fields


def make(n, dimension, first_id=0):
    rng = np.random.default_rng(n + dimension)
    return Particles({"id": np.arange(first_id, first_id + n),
                      "position": rng.normal(size=(n, dimension)),
                      "velocity": rng.normal(size=(n, dimension))})


def test_particle_fields_resolve_the_vector_shape():
    for d in (1, 2, 3):
        fields = particle_fields(d)
        assert list(fields) == list(FIELDS)
        assert fields["position"][1] == (d,) and fields["velocity"][1] == (d,)
        assert fields["pressure"][1] == () and fields["id"][1] == ()


@pytest.mark.parametrize("dimension", [2, 3])
def test_dimension_comes_from_the_arrays(dimension):
    particles = make(5, dimension)
    assert particles.dimension == dimension
    assert particles.position.shape == (5, dimension)
    # Fields not given are filled in, vector fields with d columns.
    only_position = Particles({"id": np.arange(4), "position": np.zeros((4, dimension))})
    assert only_position.velocity.shape == (4, dimension)
    assert np.all(only_position.kind == FLUID) and np.all(only_position.body == -1)
    selected = particles.select(np.array([3, 1]))
    assert selected.dimension == dimension and selected.position.shape == (2, dimension)
    both = Particles.concatenate([particles, make(2, dimension, first_id=5)], n_owned=6)
    assert both.dimension == dimension and both.position.shape == (7, dimension)
    assert both.n_owned == 6 and both.n_ghost == 1


def test_empty_and_default_dimension():
    assert Particles.empty().position.shape == (0, 2)
    assert Particles.empty(dimension=3).velocity.shape == (0, 3)
    assert Particles.concatenate([], dimension=3).position.shape == (0, 3)
    # Nothing tells d: the default is 2.
    assert Particles({"id": np.arange(3)}).position.shape == (3, 2)
    assert Particles({"id": np.arange(3)}, dimension=3).position.shape == (3, 3)


def test_inconsistent_shapes_are_refused():
    with pytest.raises(ValueError, match="velocity"):
        Particles({"id": np.arange(3), "position": np.zeros((3, 3)),
                   "velocity": np.zeros((3, 2))})
    with pytest.raises(ValueError, match="position"):
        Particles({"id": np.arange(3), "position": np.zeros((3, 2))}, dimension=3)


def test_3d_particles_pack_in_field_order():
    from parmps.parallel.exchange import pack, unpack_new
    particles = make(6, 3)
    arrays = [particles.arrays[name] for name in FIELDS]
    index = np.array([4, 0, 2])
    rebuilt = Particles(dict(zip(FIELDS, unpack_new(pack(arrays, index), arrays))))
    assert rebuilt.dimension == 3
    for name in FIELDS:
        np.testing.assert_array_equal(rebuilt.arrays[name], particles.arrays[name][index])
