"""Closed shells (issue 24 item 3): generated and read meshes, their checks, spring pairs,
the lattice inside them, and a shell body that keeps its enclosed volume."""

import math

import meshio
import numpy as np
import pytest

import parmps
from conftest import error_lines, run_parmps
from parmps import config, schema, validation
from parmps.core.geometry import nearest_on_surface, surface_distance, winding_number
from parmps.errors import CaseError
from parmps.geometry import mesh, shapes
from parmps.geometry.mesh import enclosed_volume
from parmps.solids.mass_spring import shell
from parmps.solids.mass_spring.model import MassSpringModel


def observed_orders(errors):
    """log2 of the ratio of successive errors at doubled refinement."""
    errors = np.abs(np.asarray(errors))
    return np.log2(errors[:-1] / errors[1:])


def assert_second_order(errors, finest=0.02, coarsest=0.1):
    """Orders that approach 2 from the coarse meshes on: within ``finest`` of 2 for
    the finest pair, within ``coarsest`` for every pair."""
    orders = observed_orders(errors)
    assert abs(orders[-1] - 2.0) < finest, (orders, errors)
    assert np.all(np.abs(orders - 2.0) < coarsest), (orders, errors)


# ---------------------------------------------------------------------------
# Volumes at refinement


def test_sphere_volume_converges_at_second_order():
    radius = 0.7
    exact = 4.0 / 3.0 * math.pi * radius ** 3
    errors = []
    for n in (4, 8, 16, 32):
        vertices, triangles = shapes.icosphere(radius, n, center=(1.0, -2.0, 3.0))
        assert len(vertices) == 10 * n * n + 2 and len(triangles) == 20 * n * n
        assert np.allclose(np.linalg.norm(vertices - (1.0, -2.0, 3.0), axis=1), radius)
        errors.append((enclosed_volume(vertices, triangles) - exact) / exact)
    # An inscribed polyhedron: always smaller, by O(h^2).
    assert all(e < 0 for e in errors)
    assert_second_order(errors)
    assert abs(errors[-1]) < 1e-3


def test_capsule_volume_converges_at_second_order():
    radius, length = 0.5, 1.25
    exact = math.pi * radius ** 2 * length + 4.0 / 3.0 * math.pi * radius ** 3
    errors = []
    for n in (4, 8, 16, 32):
        vertices, triangles = shapes.capsule(radius, length, frequency=n)
        extent = np.ptp(vertices, axis=0)
        assert extent == pytest.approx([2 * radius, 2 * radius, length + 2 * radius])
        # Every vertex lies on the capsule: at distance R from its axis segment.
        z = np.clip(vertices[:, 2], -length / 2, length / 2)
        axis_point = np.column_stack([np.zeros_like(z), np.zeros_like(z), z])
        assert np.allclose(np.linalg.norm(vertices - axis_point, axis=1), radius)
        errors.append((enclosed_volume(vertices, triangles) - exact) / exact)
    assert all(e < 0 for e in errors)
    assert_second_order(errors)
    assert abs(errors[-1]) < 1e-3


def evans_fung_volume(diameter, coefficients=shapes.RBC_COEFFICIENTS, points=40):
    """V = int_0^R 2 z(r) 2 pi r dr by Gauss-Legendre in theta, r = R sin(theta): the
    square root of the profile becomes cos(theta) and the integrand a smooth polynomial
    in sin and cos."""
    nodes, weights = np.polynomial.legendre.leggauss(points)
    theta = (nodes + 1.0) * math.pi / 4.0
    r = 0.5 * diameter * np.sin(theta)
    half = shapes.rbc_half_thickness(r, diameter, coefficients)
    integrand = 4.0 * math.pi * half * r * 0.5 * diameter * np.cos(theta)
    return float(np.sum(weights * integrand)) * math.pi / 4.0


def test_evans_fung_profile_has_the_measured_thicknesses():
    # Evans & Fung (1972): D = 7.82 um, 0.81 um thick at the centre, 2.58 +- 0.27 um at
    # the thickest; about 94 um^3 for this mean shape.
    r = np.linspace(0.0, shapes.RBC_DIAMETER / 2, 100001)
    half = shapes.rbc_half_thickness(r)
    assert 2 * half[0] == pytest.approx(0.81e-6, rel=2e-3)
    assert abs(2 * half.max() - 2.58e-6) < 0.27e-6
    volume = evans_fung_volume(shapes.RBC_DIAMETER)
    assert volume == pytest.approx(94.1e-18, rel=1e-3)
    # The quadrature is converged: half the points give the same number.
    assert evans_fung_volume(shapes.RBC_DIAMETER, points=20) == pytest.approx(volume, rel=1e-12)


def test_red_blood_cell_volume_converges_to_the_evans_fung_integral():
    diameter = 8.0e-6
    exact = evans_fung_volume(diameter)
    errors = []
    for n in (8, 16, 32, 64):
        vertices, triangles = shapes.red_blood_cell(diameter, frequency=n)
        # Every vertex is on the profile, and the rim is the widest ring.
        # z^2 = g^2 (1 - (2 rho/D)^2) written without the square root, which loses
        # digits at the rim.
        rho = np.hypot(vertices[:, 0], vertices[:, 1])
        s = (rho / diameter) ** 2
        c0, c1, c2 = shapes.RBC_COEFFICIENTS
        g = diameter * (c0 + c1 * s + c2 * s * s)
        assert np.allclose(4 * s + (vertices[:, 2] / g) ** 2, 1.0, rtol=0.0, atol=1e-12)
        assert rho.max() == pytest.approx(diameter / 2)
        mesh.check_closed_surface("rbc", vertices, triangles)
        errors.append((enclosed_volume(vertices, triangles) - exact) / exact)
    assert_second_order(errors)
    assert abs(errors[-1]) < 1e-3


# ---------------------------------------------------------------------------
# Spring pairs


@pytest.mark.parametrize("make", [
    lambda: shapes.icosphere(1.0, 5),
    lambda: shapes.capsule(1.0, 3.0, edge_length=0.3),
    lambda: shapes.red_blood_cell(frequency=6),
])
def test_edges_and_bending_pairs_obey_eulers_formula(make):
    vertices, triangles = make()
    edges, bending = mesh.edges_and_bending(triangles)
    n_v, n_e, n_f = len(vertices), len(edges), len(triangles)
    assert 2 * n_e == 3 * n_f
    assert n_v - n_e + n_f == 2
    assert len(np.unique(edges, axis=0)) == n_e and np.all(edges[:, 0] < edges[:, 1])
    # One bending pair per edge: the third corners of the edge's two triangles.
    assert len(bending) == n_e
    faces = {frozenset(t) for t in triangles.tolist()}
    for (i, j), (k, l) in zip(edges.tolist(), bending.tolist()):
        assert frozenset((i, j, k)) in faces and frozenset((i, j, l)) in faces and k != l


def test_node_areas_share_out_the_whole_area_which_converges():
    errors = []
    for n in (8, 16, 32):
        vertices, triangles = shapes.icosphere(2.0, n)
        area = mesh.node_areas(vertices, triangles)
        assert np.all(area > 0)
        assert area.sum() == pytest.approx(mesh.triangle_areas(vertices, triangles).sum(),
                                           rel=1e-12)
        errors.append(area.sum() / (4 * math.pi * 4.0) - 1.0)
    assert_second_order(errors)


# ---------------------------------------------------------------------------
# Refusals: one line naming the mesh and what is wrong


def tetrahedron(offset=(0.0, 0.0, 0.0)):
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) + offset
    return vertices, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def refused(vertices, triangles, match):
    with pytest.raises(CaseError, match=match) as info:
        mesh.check_closed_surface("mesh 'hand.stl'", vertices, triangles)
    message = str(info.value)
    assert "\n" not in message and message.startswith("mesh 'hand.stl': ")
    return message


def test_a_good_mesh_passes_and_gives_its_volume():
    assert mesh.check_closed_surface("tet", *tetrahedron()) == pytest.approx(1 / 6)


def test_an_open_mesh_is_refused_with_its_open_edges_counted():
    vertices, triangles = shapes.icosphere(1.0, 2)
    message = refused(vertices, triangles[1:], "not closed: 3 open edges")
    assert "e.g. the edge between vertices" in message


def test_a_non_manifold_edge_is_refused():
    # Two tetrahedra sharing the edge 0-1: four triangles on it.
    vertices, triangles = tetrahedron()
    more = np.array([[0, 0, 0], [1, 0, 0], [0.5, -1, 0], [0.5, -0.5, -1]], float)
    second = np.array([[0, 4, 1], [0, 1, 5], [0, 5, 4], [1, 4, 5]])
    both = np.concatenate([vertices, more[2:]])
    refused(both, np.concatenate([triangles, second]),
            "1 non-manifold edges .on more than two triangles., e.g. the edge between "
            "vertices 0 and 1")


def test_a_non_manifold_vertex_is_refused():
    # Two closed tetrahedra touching at vertex 3 only.
    vertices, triangles = tetrahedron()
    apex_down = np.array([[0, 0, 2], [1, 0, 2], [0, 1, 2]], float)
    second = np.array([[4, 5, 6], [4, 3, 5], [4, 6, 3], [5, 3, 6]])
    refused(np.concatenate([vertices, apex_down]), np.concatenate([triangles, second]),
            "1 non-manifold vertices .* vertex 3 at .0, 0, 1.")


def test_an_inconsistently_oriented_mesh_is_refused():
    vertices, triangles = shapes.icosphere(1.0, 2)
    triangles = triangles.copy()
    triangles[7] = triangles[7, ::-1]
    refused(vertices, triangles, "inconsistent orientation: 3 edges run the same way")


def test_an_inward_mesh_is_refused_not_reversed():
    vertices, triangles = shapes.icosphere(1.0, 2)
    refused(vertices, triangles[:, ::-1], "oriented inward .*reverse the triangles")


def test_a_degenerate_triangle_is_refused():
    # A tetrahedron with vertex 4 in the middle of edge 1-2, which a flat triangle
    # 1-2-4 closes: closed and consistently oriented, but that triangle has no area.
    vertices = np.concatenate([tetrahedron()[0], [[0.5, 0.5, 0.0]]])
    triangles = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 4, 3], [4, 2, 3], [1, 2, 4]])
    refused(vertices, triangles, "1 degenerate triangles .zero area., e.g. triangle 5")


def test_two_separate_surfaces_are_refused():
    first, triangles = tetrahedron()
    second = first + (3.0, 0.0, 0.0)
    refused(np.concatenate([first, second]), np.concatenate([triangles, triangles + 4]),
            r"the mesh is 2 separate closed surfaces \(those of vertices 0, 4\); a shell "
            r"body is one surface")


def test_surface_parts_label_each_part_by_its_least_vertex():
    vertices, triangles = shapes.icosphere(1.0, 6)
    assert np.all(mesh.surface_parts(triangles, len(vertices)) == 0)
    n = len(vertices)
    # Three spheres, the middle one's vertices listed in reverse.
    relabel = np.arange(n)[::-1] + n
    both = np.concatenate([triangles, relabel[triangles], triangles + 2 * n])
    parts = mesh.surface_parts(both, 3 * n)
    assert np.array_equal(parts, np.repeat([0, n, 2 * n], n))


def test_an_unused_vertex_is_refused():
    vertices, triangles = tetrahedron()
    refused(np.concatenate([vertices, [[5.0, 5.0, 5.0]]]), triangles,
            "1 unused vertices .* vertex 4 at .5, 5, 5.")


# ---------------------------------------------------------------------------
# Files


def test_an_stl_written_by_meshio_reads_back_merged_with_the_same_volume(tmp_path):
    vertices, triangles = shapes.icosphere(0.3, 6, center=(0.1, 0.2, 0.3))
    path = tmp_path / "sphere.stl"
    meshio.write(path, meshio.Mesh(vertices, [("triangle", triangles)]), binary=True)
    read_vertices, read_triangles = mesh.read_mesh(path)
    # STL stores 3 corners per triangle: 3 x 720 points become the 362 vertices again.
    assert len(read_vertices) == len(vertices) and len(read_triangles) == len(triangles)
    volume = mesh.check_closed_surface(str(path), read_vertices, read_triangles)
    # Binary STL is single precision.
    assert volume == pytest.approx(enclosed_volume(vertices, triangles), rel=1e-6)


def test_corners_that_differ_by_rounding_are_merged(tmp_path):
    # A triangle soup whose copies of a vertex differ in the last digits (as an exporter
    # that recomputes them writes): meshio's exact merge keeps them apart, read_mesh not.
    vertices, triangles = shapes.capsule(1.0, 2.0, frequency=5)
    soup = vertices[triangles].reshape(-1, 3)
    h = np.median(mesh.edge_lengths(vertices, triangles))
    soup = soup + 1e-3 * mesh.MERGE_TOLERANCE * h * np.random.default_rng(1).uniform(
        -1, 1, soup.shape)
    path = tmp_path / "soup.stl"
    cells = np.arange(len(soup)).reshape(-1, 3)
    meshio.write(path, meshio.Mesh(soup, [("triangle", cells)]), binary=False)
    assert len(meshio.read(path).points) == len(soup)
    read_vertices, read_triangles = mesh.read_mesh(path)
    assert len(read_vertices) == len(vertices)
    volume = mesh.check_closed_surface("soup", read_vertices, read_triangles)
    assert volume == pytest.approx(enclosed_volume(vertices, triangles), rel=1e-9)


def test_a_gmsh_file_keeps_its_triangles_and_skips_its_curves_and_points(tmp_path):
    vertices, triangles = shapes.icosphere(1.0, 3)
    path = tmp_path / "sphere.msh"
    cells = [("vertex", np.array([[0]])), ("line", triangles[:5, :2]), ("triangle", triangles)]
    meshio.write(path, meshio.Mesh(vertices, cells), file_format="gmsh22")
    read_vertices, read_triangles = mesh.read_mesh(path)
    assert len(read_vertices) == len(vertices) and len(read_triangles) == len(triangles)
    assert mesh.check_closed_surface("msh", read_vertices, read_triangles) == pytest.approx(
        enclosed_volume(vertices, triangles))


def test_quads_are_split_and_other_cells_refused(tmp_path):
    cube = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    quads = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3],
                      [0, 4, 6, 2], [1, 3, 7, 5]])
    path = tmp_path / "cube.vtk"
    meshio.write(path, meshio.Mesh(cube, [("quad", quads)]))
    vertices, triangles = mesh.read_mesh(path)
    assert len(triangles) == 12
    assert mesh.check_closed_surface("cube", vertices, triangles) == pytest.approx(1.0)
    meshio.write(tmp_path / "tet.vtk", meshio.Mesh(cube[:4], [("tetra", [[0, 1, 2, 4]])]))
    with pytest.raises(CaseError, match="tet.vtk.*has tetra cells; a shell is a surface"):
        mesh.read_mesh(tmp_path / "tet.vtk")
    with pytest.raises(CaseError, match="missing.stl.*cannot be read"):
        mesh.read_mesh(tmp_path / "missing.stl")


# ---------------------------------------------------------------------------
# The lattice inside a surface


def check_fill(points, spacing, distance, band):
    """Lattice points (of the lattice spacing (i, j, k)) farther than ``band`` from the
    surface are inside the fill exactly when the analytic shape has them inside
    (``distance`` < 0)."""
    lower, upper = points.min(axis=0), points.max(axis=0)
    axes = [np.arange(math.floor(a / spacing) - 1, math.ceil(b / spacing) + 2) * spacing
            for a, b in zip(lower, upper)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    side = distance(grid)
    clear = np.abs(side) > band
    filled = {tuple(k) for k in np.round(points / spacing).astype(int).tolist()}
    inside = np.array([tuple(k) in filled for k in np.round(grid / spacing).astype(int)
                       .tolist()])
    assert np.array_equal(inside[clear], side[clear] < 0)


def sag_bound(vertices, triangles, radius):
    """How far an inscribed mesh may lie inside its surface of curvature radius R: a
    triangle of circumradius rho <= its longest edge / sqrt(3) sags by rho^2/(2R)."""
    return mesh.edge_lengths(vertices, triangles).max() ** 2 / (6.0 * radius)


# A lattice origin in general position: no lattice point on the analytic surface.
GENERIC = np.array([0.137, 0.291, 0.613])


def check_count(vertices, triangles, spacing, exact, radius):
    """The fill's points times l0^3 against the analytic volume: the lattice-point
    discrepancy of a smooth convex body grows slower than its surface in lattice
    units, under (R/l0)^1.5 points, a relative (l0/R)^1.5."""
    points = mesh.fill_inside(vertices, triangles, spacing, origin=GENERIC * spacing)
    assert abs(len(points) * spacing ** 3 - exact) / exact < (spacing / radius) ** 1.5


@pytest.mark.parametrize("spacing", [0.1, 0.05])
def test_sphere_fill_matches_the_ball_and_its_volume(spacing):
    radius = 1.0
    vertices, triangles = shapes.icosphere(radius, 16)
    # A lattice through the centre: columns run through vertices and along edges.
    points = mesh.fill_inside(vertices, triangles, spacing)
    check_fill(points, spacing, lambda p: np.linalg.norm(p, axis=1) - radius,
               sag_bound(vertices, triangles, radius))
    check_count(vertices, triangles, spacing, 4.0 / 3.0 * math.pi * radius ** 3, radius)


@pytest.mark.parametrize("spacing", [0.1, 0.05])
def test_capsule_fill_matches_the_capsule_and_its_volume(spacing):
    radius, length = 0.5, 1.0
    # Octahedral caps put vertices and edges right on lattice columns and rows: the
    # columns through them must still cross the surface exactly once each way.
    vertices, triangles = shapes.capsule(radius, length, frequency=16)
    points = mesh.fill_inside(vertices, triangles, spacing)

    def distance(p):
        z = np.clip(p[:, 2], -length / 2, length / 2)
        return np.linalg.norm(p - np.column_stack([0 * z, 0 * z, z]), axis=1) - radius

    check_fill(points, spacing, distance, sag_bound(vertices, triangles, radius))
    exact = math.pi * radius ** 2 * length + 4.0 / 3.0 * math.pi * radius ** 3
    check_count(vertices, triangles, spacing, exact, radius)


@pytest.mark.parametrize("make, spacing", [
    (lambda: shapes.capsule(0.5, 1.0, frequency=8), 0.125),
    (lambda: shapes.red_blood_cell(8.0, frequency=8), 0.25),
])
def test_fill_points_inside_and_the_winding_number_agree(make, spacing):
    vertices, triangles = make()
    # A lattice through the origin: its columns run through the poles and the
    # capsule's vertical edges, and some of its points lie on the surface.
    points = mesh.fill_inside(vertices, triangles, spacing)
    axes = [np.arange(math.floor(a / spacing) - 1, math.ceil(b / spacing) + 2) * spacing
            for a, b in zip(vertices.min(axis=0), vertices.max(axis=0))]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    inside = mesh.points_inside(grid, vertices, triangles)
    # The same rays: the same answer, points on the surface included.
    assert np.array_equal(np.sort(np.round(points / spacing).astype(int), axis=0),
                          np.sort(np.round(grid[inside] / spacing).astype(int), axis=0))
    winding = winding_number(grid, vertices, triangles)
    # Off the surface the winding number is 0 or 1 to rounding; on it, about 1/2.
    clear = np.abs(winding - np.round(winding)) < 0.4
    assert clear.sum() > 0.98 * len(grid) and 0 < inside.sum() < len(grid)
    assert np.array_equal(inside[clear], np.round(winding[clear]) == 1)


def test_points_inside_random_points_against_the_winding_number():
    vertices, triangles = shapes.red_blood_cell(8.0, frequency=12, center=(0.3, -0.2, 0.1))
    rng = np.random.default_rng(3)
    lower, upper = vertices.min(axis=0) - 0.5, vertices.max(axis=0) + 0.5
    points = rng.uniform(lower, upper, size=(4000, 3))
    inside = mesh.points_inside(points, vertices, triangles)
    winding = winding_number(points, vertices, triangles)
    assert np.all(np.abs(winding - np.round(winding)) < 1e-6)
    assert np.array_equal(inside, np.round(winding) == 1)
    assert 0.1 < inside.mean() < 0.9


def test_the_winding_number_on_the_surface_is_the_share_of_directions_inside():
    # A unit cube of triangles: a point exactly in a face's plane sees that face
    # edge-on (counted 0, the mean of its two one-sided limits): 1/2 at a face's
    # centre, 1/4 at an edge's midpoint (a right dihedral angle), 1/8 at a corner.
    cube = np.array([[x, y, z] for z in (0, 1) for y in (0, 1) for x in (0, 1)], float)
    quads = np.array([[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3],
                      [0, 4, 6, 2], [1, 3, 7, 5]])
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    points = np.array([[0.5, 0.5, 1.0], [0.5, 0.0, 0.0], [1.0, 1.0, 1.0], [0.5, 0.5, 0.5],
                       [0.5, 0.5, 1.5]])
    assert winding_number(points, cube, triangles) == pytest.approx(
        [0.5, 0.25, 0.125, 1.0, 0.0], abs=1e-12)


# ---------------------------------------------------------------------------
# Shell bodies in cases


def case_text(body, dimension=3):
    lower = [-1.0] * dimension
    upper = [1.0] * dimension
    gravity = [0.0] * dimension
    return (f"[domain]\nlower = {lower}\nupper = {upper}\n[physics]\ngravity = {gravity}\n"
            f"[time]\nend = 0.01\nfixed_dt = 1e-3\n[[body]]\n{body}\n")


def build(body, dimension=3):
    case = schema.validate(config.load_text(case_text(body, dimension)))
    return MassSpringModel.from_case(case).bodies[0]


def test_a_shell_body_has_edge_and_bending_springs_and_its_volume():
    body = build('type = "shell"\nshape = "sphere"\nradius = 0.5\nrefinement = 4\n'
                 'stiffness = 10.0\nbending_stiffness = 2.0\nsurface_density = 3.0')
    assert body.n_nodes == 162 and len(body.springs) == 2 * 480
    assert np.count_nonzero(body.stiffness == 2.0) == 480
    assert body.mass.sum() == pytest.approx(3.0 * 4 * math.pi * 0.25, rel=2e-2)
    assert body.volume_constraint
    assert body.rest_volume == pytest.approx(4 / 3 * math.pi * 0.125, rel=4e-2)


def test_a_capsule_along_x_puts_a_line_of_nodes_on_top():
    body = build('type = "shell"\nshape = "capsule"\nradius = 0.2\nlength = 0.4\n'
                 'axis = "x"\nspacing = 0.05\nstiffness = 10.0\nnode_mass = 0.01\n'
                 'pinned = "bottom"')
    assert np.ptp(body.position, axis=0) == pytest.approx([0.8, 0.4, 0.4])
    top = body.position[:, 2] >= body.position[:, 2].max() - 1e-12
    assert top.sum() == 9 and body.pinned.sum() == 9


def test_a_red_blood_cell_body_turned_to_y():
    body = build('type = "shell"\nshape = "red_blood_cell"\naxis = "y"\nrefinement = 8\n'
                 'center = [0.1, 0.2, 0.3]\nstiffness = 1e-6\nsurface_density = 1e-3')
    extent = np.ptp(body.position, axis=0)
    assert extent[[0, 2]] == pytest.approx([shapes.RBC_DIAMETER] * 2)
    assert extent[1] == pytest.approx(2 * shapes.rbc_half_thickness(
        np.linspace(0, shapes.RBC_DIAMETER / 2, 100001)).max(), rel=1e-3)
    assert body.position.mean(axis=0) == pytest.approx([0.1, 0.2, 0.3])
    assert body.rest_volume == pytest.approx(evans_fung_volume(shapes.RBC_DIAMETER), rel=3e-2)


def test_a_mesh_file_body_is_read_and_moved(tmp_path):
    vertices, triangles = shapes.capsule(0.1, 0.2, frequency=4)
    path = tmp_path / "capsule.obj"
    meshio.write(path, meshio.Mesh(vertices, [("triangle", triangles)]))
    body = build(f'type = "shell"\nshape = "file"\nmesh = "{path}"\ncenter = [0.5, 0, 0]\n'
                 f'stiffness = 5.0\nnode_mass = 0.01\nvolume_constraint = false')
    assert body.n_nodes == len(vertices) and len(body.facets) == len(triangles)
    assert body.position.mean(axis=0) == pytest.approx([0.5, 0.0, 0.0])
    assert body.rest_volume == pytest.approx(enclosed_volume(vertices, triangles))
    assert not body.volume_constraint and len(body.springs) == 3 * len(triangles) // 2


@pytest.mark.parametrize("body, dimension, match", [
    ('type = "shell"\nradius = 0.5\nstiffness = 1.0\nnode_mass = 1.0', 2,
     "shell.* is a closed surface in 3D; this case is 2D"),
    ('type = "shell"\nshape = "file"\nstiffness = 1.0\nnode_mass = 1.0', 3,
     'shape = "file" needs mesh'),
    ('type = "shell"\nradius = 0.5\nspacing = 0.2\nnode_mass = 1.0', 3,
     "missing key 'stiffness'"),
    ('type = "shell"\nradius = 0.5\nspacing = 0.2\nstiffness = 1.0', 3,
     "node_mass .kg. or surface_density"),
    ('type = "shell"\nradius = 0.5\nspacing = 0.2\nstiffness = 1.0\nnode_mass = 1.0\n'
     'nx = 3', 3, r"body\[0\].nx does not apply to a shell"),
    ('nx = 2\nny = 2\nnz = 2\nspacing = 0.1\nstiffness = 1.0\nnode_mass = 1.0\n'
     'radius = 0.5', 3, r'body\[0\].radius applies to shell bodies only'),
    ('type = "shell"\nshape = "red_blood_cell"\nradius = 0.5\nstiffness = 1.0\n'
     'node_mass = 1.0', 3, r'\.radius does not apply to shape = "red_blood_cell" \(it reads '
     r'diameter, axis, spacing, refinement, geodesic_base and center\)'),
    ('type = "shell"\nradius = 0.5\nspacing = 0.1\nrefinement = 3\nstiffness = 1.0\n'
     'node_mass = 1.0', 3, "give spacing .* or refinement, not both"),
    ('type = "shell"\nshape = "capsule"\nradius = 0.5\nlength = 1.0\nspacing = 1e-4\n'
     'stiffness = 1.0\nnode_mass = 1.0', 3,
     r"body\[0\]: capsule: refinement 7854 makes 1.12e\+09 triangles .more than 2e\+06.; "
     r"check the "
     r"units of spacing"),
])
def test_bad_shell_bodies_are_refused_in_one_line(body, dimension, match):
    with pytest.raises(CaseError, match=match):
        build(body, dimension)


def test_a_bad_mesh_file_is_refused_before_the_run_naming_it(tmp_path):
    vertices, triangles = shapes.icosphere(0.5, 3)
    path = tmp_path / "leaky.stl"
    meshio.write(path, meshio.Mesh(vertices, [("triangle", triangles[1:])]))
    case = tmp_path / "leaky.toml"
    case.write_text(case_text(f'name = "cell"\ntype = "shell"\nshape = "file"\n'
                              f'mesh = "{path}"\nstiffness = 1.0\nnode_mass = 1.0'))
    result = run_parmps([case, "--check"], timeout=120)
    assert result.returncode == 2
    (line,) = error_lines(result.stderr)
    assert f"body[0] 'cell'.mesh '{path}'" in line and "not closed: 3 open edges" in line


def test_the_squeezed_shell_keeps_its_volume_and_the_free_one_does_not(tmp_path):
    # validation/shell_squeeze_3d: both cases to their end (1.5 s, about 15 s together).
    check = validation.load("shell_squeeze_3d")
    worst = {}
    for name, case in (("constrained", check.case_path), ("free", check.other_cases["unconstrained"])):
        out = tmp_path / name
        result = run_parmps([case, "-o", out], timeout=300)
        assert result.returncode == 0, result.stderr[-2000:]
        with parmps.open_result(out) as saved:
            error = np.asarray(saved.bodies["capsule"]["volume_error"])
        assert len(error) == 1500
        worst[name] = np.abs(error).max()
    assert worst["constrained"] <= check.tolerance["volume_error"]
    low, high = check.tolerance["unconstrained_volume_error"]
    assert low <= worst["free"] <= high


# -- the fluid beside a shell ---------------------------------------------------------------


def _brute_distance(points, vertices, triangles):
    """Distance to every triangle, by projecting on its plane or else its three edges."""
    from parmps.core.geometry import _closest_on_triangle
    corners = vertices[triangles]
    return np.array([math.sqrt(min(_closest_on_triangle(p, *c)[0] for c in corners))
                     for p in points])


def test_the_distance_to_a_surface_is_the_least_over_its_triangles():
    vertices, triangles = shapes.capsule(0.03, 0.04, 0.01)
    rng = np.random.default_rng(3)
    points = rng.uniform(vertices.min(axis=0) - 0.02, vertices.max(axis=0) + 0.02, (400, 3))
    exact = _brute_distance(points, vertices, triangles)
    near = surface_distance(points, vertices, triangles, 0.008)
    within = exact <= 0.008
    assert 50 < within.sum() < 350
    np.testing.assert_allclose(near[within], exact[within], rtol=0, atol=1e-15)
    assert np.all(np.isinf(near[~within]))
    # The nearest point: its triangle's corners weighed by the barycentric weights.
    distance, triangle, weights = nearest_on_surface(points, vertices, triangles, 0.008)
    np.testing.assert_array_equal(distance, near)
    assert np.all(triangle[~within] == -1) and np.all(weights[~within] == 0.0)
    assert weights.min() >= 0.0
    np.testing.assert_allclose(weights[within].sum(axis=1), 1.0, rtol=0, atol=1e-14)
    nearest = np.einsum("kc,kcd->kd", weights[within], vertices[triangles[triangle[within]]])
    np.testing.assert_allclose(np.linalg.norm(points[within] - nearest, axis=1),
                               exact[within], rtol=0, atol=1e-15)
    # On a sphere: |r - R| to the inscribed mesh's accuracy (its sag, below 1 % of R here).
    vertices, triangles = shapes.icosphere(1.0, 16)
    radius = np.linalg.norm(points - points.mean(axis=0), axis=1)
    direction = (points - points.mean(axis=0)) / radius[:, None]
    shells = direction * rng.uniform(0.8, 1.2, len(points))[:, None]
    distance = surface_distance(shells, vertices, triangles, 0.25)
    np.testing.assert_allclose(distance, np.abs(np.linalg.norm(shells, axis=1) - 1.0),
                               rtol=0, atol=2.2e-3)


@pytest.mark.parametrize("edge", [0.5, 1.0, 2.0])
def test_the_fluid_left_out_beside_a_shell_is_as_many_points_as_it_has_nodes(edge):
    """A sphere of radius 5 l0 on the fluid's lattice: the points within the clearance of
    its surface number its nodes, within the lattice's sampling of a shell (a tenth), where
    the mesh is at least as fine as the fluid; a coarser mesh clears half a spacing, which
    holds more points than the mesh has nodes."""
    spacing = 1.0
    vertices, triangles = shapes.icosphere(5.0, edge_length=edge * spacing)
    clearance = shell.fluid_clearance(vertices, triangles, spacing)
    per_node = mesh.triangle_areas(vertices, triangles).sum() / len(vertices)
    assert clearance == pytest.approx(max(0.5, 0.5 / per_node))
    axis = np.arange(-7, 8) + 0.5
    lattice = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), axis=-1).reshape(-1, 3)
    taken = shell.displaced_by_shell(lattice, vertices, triangles, spacing)
    distance = surface_distance(lattice, vertices, triangles, 3.0)
    np.testing.assert_array_equal(taken, distance < clearance)
    if clearance > 0.5:
        assert taken.sum() == pytest.approx(len(vertices), rel=0.1)
    else:
        assert taken.sum() > len(vertices)
