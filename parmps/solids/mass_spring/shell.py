"""Closed triangle meshes for shell bodies (issue 24 item 3).

A shell is a closed, outward-oriented triangle mesh: its vertices are the body's
nodes, its edges carry springs, a bending spring joins the two vertices opposite
each edge, and its triangles are the facets whose enclosed volume Hong et al.'s
constraint keeps. This module makes, reads and checks such meshes; arrays in,
arrays out, no Python loop over triangles.

- Generators: :func:`icosphere`, :func:`capsule`, :func:`red_blood_cell`, each
  returning ``(vertices (n, 3), triangles (m, 3))`` with outward triangles.
- :func:`read_mesh` reads a file through meshio and merges duplicate vertices
  (STL stores each triangle's corners separately).
- :func:`check_closed_surface` refuses a mesh that is not a closed, consistently
  and outward oriented, manifold surface, in one line naming its source.
- :func:`edges_and_bending` gives the spring pairs, :func:`node_areas` the lumped
  area of every node, :func:`points_inside` / :func:`fill_inside` the lattice
  points inside the surface, :func:`displaced_by_shell` the fluid's points a
  shell's nodes take the place of (docs/shells.md, A shell in a fluid).

Geodesic spheres: every face of a base polyhedron (icosahedron or octahedron) is
cut into frequency^2 triangles on a barycentric grid and the grid points are
projected on the sphere. Frequency 2^k is k levels of midpoint subdivision.
"""

import logging
import math

import numpy as np

from parmps.config import ZERO, Key
from parmps.core.geometry import surface_distance
from parmps.errors import CaseError
from parmps.solids.mass_spring.surface import enclosed_volume

log = logging.getLogger(__name__)

# Evans & Fung (1972), the resting human red blood cell: half-thickness
# z(r) = D sqrt(1 - 4 r^2/D^2) (c0 + c1 r^2/D^2 + c2 r^4/D^4), D = 7.82 um.
# (Written with (2r/D)^2 the same shape reads (D/4) sqrt(1 - (2r/D)^2)
# (0.2072 + 2.0026 (2r/D)^2 - 1.1228 (2r/D)^4).) It gives the measured
# thicknesses: 0.81 um at the centre, 2.57 um at the rim.
RBC_DIAMETER = 7.82e-6
RBC_COEFFICIENTS = (0.0518, 2.0026, -4.491)

# Duplicate vertices of a file closer than this share of the median edge are one.
MERGE_TOLERANCE = 1e-5

# A triangle with less than this share of the median edge squared has no area.
DEGENERATE_AREA = 1e-10

# A generated shell larger than this is a unit mistake (spacing in mm for a body in
# m), not a body: a mass-spring body of a case has thousands of nodes, and this many
# triangles already take gigabytes to build.
MAX_TRIANGLES = 2_000_000


def _icosahedron():
    t = (1.0 + math.sqrt(5.0)) / 2.0
    vertices = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0],
                         [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                         [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=float)
    faces = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11],
                      [1, 5, 9], [5, 11, 4], [11, 10, 2], [10, 7, 6], [7, 1, 8],
                      [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                      [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    return vertices / np.linalg.norm(vertices, axis=1, keepdims=True), faces


def _octahedron():
    vertices = np.array([[1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0],
                         [0, 0, 1], [0, 0, -1]], dtype=float)
    faces = np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4],
                      [1, 0, 5], [2, 1, 5], [3, 2, 5], [0, 3, 5]])
    return vertices, faces


def _face_grid(n):
    """One face cut n times: grid (i, j) with i + j <= n, and its n^2 triangles."""
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    i, j = i[keep], j[keep]
    local = np.full((n + 1, n + 1), -1)
    local[i, j] = np.arange(len(i))
    up = (i + j) <= n - 1
    down = (i + j) <= n - 2
    iu, ju, idn, jdn = i[up], j[up], i[down], j[down]
    # Both kinds run counter-clockwise in (i, j), as the face's corners a, b, c do.
    cells = np.concatenate([
        np.column_stack([local[iu, ju], local[iu + 1, ju], local[iu, ju + 1]]),
        np.column_stack([local[idn + 1, jdn], local[idn + 1, jdn + 1], local[idn, jdn + 1]])])
    return i, j, cells


def geodesic(base_vertices, base_faces, frequency):
    """Unit geodesic sphere: each base face cut ``frequency`` times along each edge.

    A grid point is an integer combination of the base vertices (weights summing
    to n); points on shared edges have the same weights from both faces, so they
    are merged exactly, without a tolerance.
    """
    n = int(frequency)
    if n < 1:
        raise ValueError(f"frequency must be >= 1, got {frequency}")
    i, j, cells = _face_grid(n)
    faces, points = len(base_faces), len(i)
    weights = np.zeros((faces, points, len(base_vertices)), dtype=np.int32)
    f = np.arange(faces)[:, None]
    weights[f, np.arange(points)[None, :], base_faces[:, 0:1]] = n - i - j
    weights[f, np.arange(points)[None, :], base_faces[:, 1:2]] = i
    weights[f, np.arange(points)[None, :], base_faces[:, 2:3]] = j
    unique, inverse = np.unique(weights.reshape(faces * points, -1), axis=0,
                                return_inverse=True)
    inverse = inverse.ravel()
    vertices = unique @ base_vertices / n
    vertices /= np.linalg.norm(vertices, axis=1, keepdims=True)
    triangles = inverse[cells[None, :, :] + points * np.arange(faces)[:, None, None]]
    return vertices, triangles.reshape(-1, 3)


def _frequency(arc, edge_length, frequency, what, faces, extra=0):
    """The geodesic frequency: given, or the least whose base-edge arc / n <= edge_length;
    refused if ``faces`` n^2 + ``extra`` triangles would exceed MAX_TRIANGLES."""
    if frequency is not None:
        if int(frequency) < 1:
            raise CaseError(f"{what}: refinement must be >= 1, got {frequency}")
        n = int(frequency)
    elif edge_length is None or not edge_length > 0:
        raise CaseError(f"{what}: give a target edge length > 0 or a refinement")
    else:
        n = max(1, math.ceil(arc / edge_length * (1.0 - 1e-12)))
    if faces * n * n + extra > MAX_TRIANGLES:
        raise CaseError(f"{what}: refinement {n} makes {faces * n * n + extra:.3g} triangles "
                        f"(more than {MAX_TRIANGLES:.0e}); check the units of spacing")
    return n


def icosphere(radius, frequency=None, edge_length=None, center=(0.0, 0.0, 0.0)):
    """Sphere of ``radius`` from the icosahedron: 10 n^2 + 2 vertices, 20 n^2 triangles.

    ``frequency`` n, or the least n whose edges are about ``edge_length`` (the
    icosahedron's edge spans an arc of arccos(1/sqrt5) radians).
    """
    n = _frequency(radius * math.acos(1.0 / math.sqrt(5.0)), edge_length, frequency,
                   "sphere", 20)
    vertices, triangles = geodesic(*_icosahedron(), n)
    return radius * vertices + np.asarray(center, dtype=float), triangles


def _ring_order(vertices, ring):
    """The ring's vertices counter-clockwise seen from +z."""
    angle = np.arctan2(vertices[ring, 1], vertices[ring, 0])
    return ring[np.argsort(angle)]


def _bands(rings):
    """Outward triangles between consecutive rings (rows of ``rings``, each
    counter-clockwise seen from +z, bottom to top): two per quad."""
    lower, upper = rings[:-1], rings[1:]
    q = np.arange(rings.shape[1])
    r = np.roll(q, -1)
    return np.concatenate([np.stack([lower[:, q], lower[:, r], upper[:, r]], axis=-1),
                           np.stack([lower[:, q], upper[:, r], upper[:, q]], axis=-1)]
                          ).reshape(-1, 3)


def capsule(radius, length, edge_length=None, frequency=None, center=(0.0, 0.0, 0.0)):
    """Capsule along z: a cylinder of ``radius`` and ``length`` closed by hemispheres.

    The caps are halves of an octahedral geodesic sphere, whose equator is a ring
    of 4n vertices at z = 0 exactly; the cylinder is rings of those 4n azimuths,
    about ``edge_length`` apart. Total height: length + 2 radius.
    """
    if not radius > 0 or length < 0:
        raise CaseError(f"capsule: radius must be > 0 and length >= 0, got {radius}, {length}")
    n = _frequency(radius * math.pi / 2.0, edge_length, frequency, "capsule", 8,
                   extra=2 * (length / edge_length) * (2 * math.pi * radius / edge_length)
                   if edge_length else 0)
    unit, triangles = geodesic(*_octahedron(), n)
    vertices = radius * unit
    equator = _ring_order(vertices, np.flatnonzero(unit[:, 2] == 0.0))
    if length == 0.0:
        return vertices + np.asarray(center, dtype=float), triangles
    segments = max(1, round(length / (edge_length or 2.0 * math.pi * radius / len(equator))))
    top = unit[:, 2] >= 0.0
    vertices[:, 2] += np.where(top, 0.5, -0.5) * length
    # The equator belongs to the top cap; the bottom cap gets copies of it below,
    # and the cylinder's inner rings come after those.
    k = len(equator)
    heights = -0.5 * length + length * np.arange(segments) / segments
    rings_xy = np.tile(vertices[equator, :2], (segments, 1))
    new = np.column_stack([rings_xy, np.repeat(heights, k)])
    first = len(vertices)
    rings = np.concatenate([first + np.arange(segments * k).reshape(segments, k),
                            equator[None, :]])
    relabel = np.arange(len(vertices))
    relabel[equator] = rings[0]
    centroid_z = unit[triangles, 2].mean(axis=1)
    triangles = np.where((centroid_z < 0.0)[:, None], relabel[triangles], triangles)
    vertices = np.concatenate([vertices, new]) + np.asarray(center, dtype=float)
    return vertices, np.concatenate([triangles, _bands(rings)])


def rbc_half_thickness(r, diameter=RBC_DIAMETER, coefficients=RBC_COEFFICIENTS):
    """Evans & Fung's half-thickness z(r) of a red blood cell of ``diameter``; arrays."""
    s = (np.asarray(r, dtype=float) / diameter) ** 2
    c0, c1, c2 = coefficients
    return diameter * np.sqrt(np.clip(1.0 - 4.0 * s, 0.0, None)) * (c0 + c1 * s + c2 * s * s)


def red_blood_cell(diameter=RBC_DIAMETER, edge_length=None, frequency=None,
                   center=(0.0, 0.0, 0.0), coefficients=RBC_COEFFICIENTS, base="octahedron"):
    """The biconcave disc of Evans & Fung (1972), axis z, scaled to ``diameter``.

    An octahedral geodesic unit sphere mapped (x, y, z) -> (R x, R y, z g(x^2 + y^2))
    with R = D/2 and g = D (c0 + c1 rho^2/4 + c2 rho^4/16): since |z| = sqrt(1 - rho^2)
    on the sphere, every vertex lands on the profile. g > 0, so the map keeps the
    triangles' orientation; the rim is the sphere's exact equator ring. ``base =
    "icosahedron"`` maps an icosahedral sphere instead (10 n^2 + 2 vertices): no ring
    on the rim, but no grid lines along x and y either.
    """
    if not diameter > 0:
        raise CaseError(f"red_blood_cell: diameter must be > 0, got {diameter}")
    if base == "icosahedron":
        n = _frequency(diameter / 2.0 * math.acos(1.0 / math.sqrt(5.0)), edge_length,
                       frequency, "red_blood_cell", 20)
        unit, triangles = geodesic(*_icosahedron(), n)
    else:
        n = _frequency(math.pi * diameter / 4.0, edge_length, frequency, "red_blood_cell", 8)
        unit, triangles = geodesic(*_octahedron(), n)
    rho2 = unit[:, 0] ** 2 + unit[:, 1] ** 2
    c0, c1, c2 = coefficients
    g = diameter * (c0 + c1 * rho2 / 4.0 + c2 * rho2 ** 2 / 16.0)
    if np.any(g <= 0.0):
        raise CaseError(f"red_blood_cell: the coefficients {coefficients} give a profile "
                        f"that crosses the mid-plane")
    vertices = np.column_stack([0.5 * diameter * unit[:, 0], 0.5 * diameter * unit[:, 1],
                                g * unit[:, 2]])
    return vertices + np.asarray(center, dtype=float), triangles


# --------------------------------------------------------------------------
# Measures


def triangle_areas(vertices, triangles):
    """Area of every triangle; shape (m,)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def edge_lengths(vertices, triangles):
    """Length of each triangle's three sides (shared sides twice); shape (m, 3)."""
    corners = vertices[triangles]
    return np.linalg.norm(corners - np.roll(corners, -1, axis=1), axis=2)


def node_areas(vertices, triangles):
    """Each vertex's lumped share of the surface: a third of every triangle it is on."""
    share = np.repeat(triangle_areas(vertices, triangles) / 3.0, 3)
    return np.bincount(triangles.ravel(), weights=share, minlength=len(vertices))


# --------------------------------------------------------------------------
# Topology


def _half_edges(triangles):
    """Every triangle's sides a->b, b->c, c->a with the vertex opposite each; (3m,) each."""
    start = triangles.ravel()
    end = triangles[:, [1, 2, 0]].ravel()
    opposite = triangles[:, [2, 0, 1]].ravel()
    return start, end, opposite


def _edge_groups(start, end):
    """Half-edges sorted by their undirected edge: (order, first of each group, counts)."""
    low, high = np.minimum(start, end), np.maximum(start, end)
    order = np.lexsort((high, low))
    low, high = low[order], high[order]
    new = np.ones(len(order), bool)
    new[1:] = (low[1:] != low[:-1]) | (high[1:] != high[:-1])
    first = np.flatnonzero(new)
    counts = np.diff(np.append(first, len(order)))
    return order, first, counts


def edges_and_bending(triangles):
    """Unique edges (E, 2) and, for each, the two vertices opposite it (E, 2).

    The mesh must be closed and manifold (every edge on exactly two triangles,
    :func:`check_closed_surface`): an edge spring joins the first pair, a bending
    spring the second.
    """
    start, end, opposite = _half_edges(np.asarray(triangles))
    order, first, counts = _edge_groups(start, end)
    if np.any(counts != 2):
        raise ValueError("edges_and_bending needs every edge on exactly two triangles")
    edges = np.sort(np.column_stack([start[order[first]], end[order[first]]]), axis=1)
    bending = np.column_stack([opposite[order[first]], opposite[order[first + 1]]])
    return edges, bending


def _vertex_fans(triangles, n_vertices):
    """Number of separate triangle fans around every vertex (1 on a manifold surface).

    Corners are (triangle, vertex) pairs; turning around a vertex maps a corner
    to the corner of the same vertex in the triangle across its outgoing side
    (needs every side shared by two oppositely oriented triangles). The orbits of
    that map are the fans; each corner takes its orbit's smallest index by pointer
    doubling, log2(valence) passes.
    """
    start, end, _ = _half_edges(triangles)
    corners = len(start)
    # The corner whose outgoing side is the twin of this one's incoming side.
    incoming_start = triangles[:, [2, 0, 1]].ravel()       # c->a is a's incoming side
    key_out = start.astype(np.int64) * n_vertices + end     # corner k: start[k] -> end[k]
    key_twin = start.astype(np.int64) * n_vertices + incoming_start  # a -> c, the twin
    sorter = np.argsort(key_out)
    turn = sorter[np.searchsorted(key_out, key_twin, sorter=sorter)]
    label = np.arange(corners)
    jump = turn
    # After p passes a label is the least over 2^p steps of its orbit, and no orbit
    # is longer than its vertex's valence.
    valence = int(np.bincount(start, minlength=n_vertices).max())
    for _ in range(max(1, valence - 1).bit_length()):
        label = np.minimum(label, label[jump])
        jump = jump[jump]
    pairs = np.unique(np.column_stack([start, label]), axis=0)
    return np.bincount(pairs[:, 0], minlength=n_vertices)


def surface_parts(triangles, n_vertices):
    """Which connected part of the mesh every vertex is on: the least vertex index of
    its part. Labels spread along the edges, each pass also jumping to the label's
    own label, until nothing changes."""
    start, end, _ = _half_edges(np.asarray(triangles))
    label = np.arange(n_vertices)
    while True:
        spread = label.copy()
        np.minimum.at(spread, start, label[end])
        spread = spread[spread]
        if np.array_equal(spread, label):
            return label
        label = spread


# --------------------------------------------------------------------------
# Checks


def _at(vertices, v):
    x, y, z = vertices[v]
    return f"({x:.6g}, {y:.6g}, {z:.6g})"


def _check_cells(source, vertices, triangles):
    """Indices in range, no unused vertex, no triangle without area."""
    n = len(vertices)
    if len(triangles) < 4:
        raise CaseError(f"{source}: {len(triangles)} triangles cannot close a surface "
                        f"(at least 4)")
    bad = (triangles < 0) | (triangles >= n)
    if bad.any():
        t = int(np.flatnonzero(bad.any(axis=1))[0])
        raise CaseError(f"{source}: triangle {t} names vertex {int(triangles[t][bad[t]][0])}, "
                        f"but the mesh has {n} vertices")
    used = np.zeros(n, bool)
    used[triangles.ravel()] = True
    if not used.all():
        v = int(np.flatnonzero(~used)[0])
        raise CaseError(f"{source}: {int((~used).sum())} unused vertices (on no triangle), "
                        f"e.g. vertex {v} at {_at(vertices, v)}; remove them")
    scale = float(np.median(edge_lengths(vertices, triangles)))
    area = triangle_areas(vertices, triangles)
    flat = area <= DEGENERATE_AREA * scale ** 2
    if flat.any():
        t = int(np.flatnonzero(flat)[0])
        raise CaseError(f"{source}: {int(flat.sum())} degenerate triangles (zero area), e.g. "
                        f"triangle {t} (vertices {', '.join(map(str, triangles[t]))}) at "
                        f"{_at(vertices, triangles[t, 0])}")


def _check_edges(source, vertices, triangles):
    """Every edge on exactly two triangles, which run along it in opposite directions."""
    start, end, _ = _half_edges(triangles)
    order, first, counts = _edge_groups(start, end)
    a, b = start[order[first]], end[order[first]]

    def example(mask):
        e = int(np.flatnonzero(mask)[0])
        i, j = sorted((int(a[e]), int(b[e])))
        return f"e.g. the edge between vertices {i} and {j} at {_at(vertices, i)}"

    open_edges = counts == 1
    if open_edges.any():
        raise CaseError(f"{source}: the surface is not closed: {int(open_edges.sum())} open "
                        f"edges (on one triangle only), {example(open_edges)}")
    shared = counts > 2
    if shared.any():
        raise CaseError(f"{source}: {int(shared.sum())} non-manifold edges (on more than two "
                        f"triangles), {example(shared)}")
    # With two triangles on every edge, one that both run along in the same
    # direction has the same start as its partner.
    same = start[order[first]] == start[order[first + 1]]
    if same.any():
        raise CaseError(f"{source}: inconsistent orientation: {int(same.sum())} edges run the "
                        f"same way in both their triangles, {example(same)}; orient every "
                        f"triangle outward")


def check_closed_surface(source, vertices, triangles):
    """Refuse, in one line starting with ``source``, a mesh that is not a closed,
    manifold, consistently and outward oriented surface. Returns its volume."""
    vertices = np.asarray(vertices, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3 or triangles.ndim != 2 \
            or triangles.shape[1] != 3:
        raise CaseError(f"{source}: a shell needs vertices (n, 3) and triangles (m, 3), got "
                        f"{vertices.shape} and {triangles.shape}")
    _check_cells(source, vertices, triangles)
    _check_edges(source, vertices, triangles)
    fans = _vertex_fans(triangles, len(vertices))
    pinched = fans > 1
    if pinched.any():
        v = int(np.flatnonzero(pinched)[0])
        raise CaseError(f"{source}: {int(pinched.sum())} non-manifold vertices (where separate "
                        f"parts of the surface touch), e.g. vertex {v} at {_at(vertices, v)}")
    parts = np.unique(surface_parts(triangles, len(vertices)))
    if len(parts) > 1:
        # One multiplier for several surfaces would let volume pass between them.
        raise CaseError(f"{source}: the mesh is {len(parts)} separate closed surfaces (those "
                        f"of vertices {', '.join(map(str, parts[:3]))}"
                        f"{', ...' if len(parts) > 3 else ''}); a shell body is one surface: "
                        f"give each its own [[body]]")
    volume = enclosed_volume(vertices, triangles)
    extent = float(np.ptp(vertices, axis=0).max())
    if volume < 0:
        raise CaseError(f"{source}: the triangles are oriented inward (enclosed volume "
                        f"{volume:.6g}); reverse the triangles: parmps refuses rather than "
                        f"reorder them")
    if volume <= 1e-12 * extent ** 3:
        raise CaseError(f"{source}: the surface encloses no volume ({volume:.6g})")
    return volume


# --------------------------------------------------------------------------
# Files


def merge_vertices(vertices, triangles, tolerance):
    """Merge vertices closer than ``tolerance`` in every coordinate; drop unused ones.

    Points are binned on 8 grids of cell ``2 tolerance``, offset by half a cell
    along each axis: two points within ``tolerance`` share a cell of at least one
    of them (per axis one offset never puts a cell boundary between them). Points
    sharing any cell get one label, by repeated minimum over cells.
    """
    vertices = np.asarray(vertices, dtype=float)
    scaled = (vertices - vertices.min(axis=0)) / (2.0 * tolerance)
    keys = []
    for shift in np.array(np.meshgrid([0.0, 0.5], [0.0, 0.5], [0.0, 0.5])).reshape(3, -1).T:
        cells = np.floor(scaled + shift).astype(np.int64)
        keys.append(np.unique(cells, axis=0, return_inverse=True)[1].ravel())
    label = np.arange(len(vertices))
    while True:
        before = label
        for cell in keys:
            least = np.full(cell.max() + 1, len(vertices))
            np.minimum.at(least, cell, label)
            label = least[cell]
        if np.array_equal(label, before):
            break
    used = np.unique(label[np.asarray(triangles).ravel()])
    index = np.full(len(vertices), -1)
    index[used] = np.arange(len(used))
    return vertices[used], index[label[np.asarray(triangles)]]


def _triangles_of(source, mesh):
    """meshio cells to triangles: quads split along their first diagonal, lines and
    points (Gmsh keeps the geometry's curves) ignored, anything else refused."""
    blocks = []
    for block in mesh.cells:
        kind, data = block.type, np.asarray(block.data, dtype=np.int64)
        if kind == "triangle":
            blocks.append(data)
        elif kind == "quad":
            blocks.append(np.concatenate([data[:, [0, 1, 2]], data[:, [0, 2, 3]]]))
        elif kind in ("vertex", "line", "line3"):
            continue
        else:
            raise CaseError(f"{source}: has {kind} cells; a shell is a surface of triangles "
                            f"(or quads), export the surface only")
    if not blocks:
        raise CaseError(f"{source}: no triangles in the file")
    return np.concatenate(blocks)


def read_mesh(path, source=None):
    """Vertices (n, 3) and triangles (m, 3) of a surface mesh file (STL, OBJ, Gmsh,
    VTK, ... through meshio), duplicates merged within MERGE_TOLERANCE of the median
    edge. ``source`` names the file in messages. The result is not checked: see
    :func:`check_closed_surface`."""
    import meshio  # only shells read files: a case without one does not import it

    source = source or f"mesh '{path}'"
    try:
        mesh = meshio.read(path)
    # meshio reports unreadable files with many exception types; each is bad input.
    except Exception as exc:  # noqa: BLE001
        raise CaseError(f"{source}: cannot be read: "
                        f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
                        ) from None
    points = np.asarray(mesh.points, dtype=float)
    if points.shape[1] == 2:
        raise CaseError(f"{source}: the points are 2D; a shell needs 3D points")
    triangles = _triangles_of(source, mesh)
    if triangles.min() < 0 or triangles.max() >= len(points):
        raise CaseError(f"{source}: a cell names a point the file does not have")
    scale = float(np.median(edge_lengths(points, triangles)))
    if not scale > 0:
        raise CaseError(f"{source}: the triangles have no size (median edge 0)")
    unused = len(points) - len(np.unique(triangles))
    vertices, triangles = merge_vertices(points, triangles, MERGE_TOLERANCE * scale)
    log.debug("%s: %d points, %d on no triangle, %d vertices after merging, %d triangles",
              source, len(points), unused, len(vertices), len(triangles))
    if unused:
        raise CaseError(f"{source}: {unused} unused vertices (on no triangle); remove them")
    return vertices, triangles


# --------------------------------------------------------------------------
# Inside the surface


def _edge_side(p, low, high):
    """orient2d(p, low, high) with p moved by (eps, eps^2): never 0 unless the edge
    projects to a point. Both triangles on an edge evaluate it with the same
    (low, high), so they agree on which side of it p lies."""
    e = (low[:, 0] - p[:, 0]) * (high[:, 1] - p[:, 1]) \
        - (low[:, 1] - p[:, 1]) * (high[:, 0] - p[:, 0])
    tie_x = low[:, 1] - high[:, 1]      # d e / d p_x
    tie_y = high[:, 0] - low[:, 0]      # d e / d p_y
    side = np.sign(e)
    side = np.where(side == 0, np.sign(tie_x), side)
    return e, np.where(side == 0, np.sign(tie_y), side)


def _crossings(xy, triangle, vertices, triangles):
    """Where vertical lines through ``xy`` (k, 2) cross ``triangle`` (k,) (indices
    into ``triangles``): (hit (k,), height of each hit, the sign of each hit's
    normal z: +1 where the line leaves an outward surface going up)."""
    tri = triangles[triangle]
    sides, values = [], []
    for k in range(3):  # the triangle's three sides a->b, b->c, c->a
        a, b = tri[:, k], tri[:, (k + 1) % 3]
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        e, side = _edge_side(xy, vertices[lo, :2], vertices[hi, :2])
        flip = np.where(a == lo, 1.0, -1.0)
        sides.append(flip * side)
        values.append(flip * e)
    a, b, c = (vertices[tri[:, k]] for k in range(3))
    normal_z = np.sign((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1])
                       - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))
    hit = (normal_z != 0) & np.all(np.array(sides) == normal_z, axis=0)
    # Barycentric height of the crossing: the side opposite a corner weighs it.
    e_ab, e_bc, e_ca = (v[hit] for v in values)
    z = (e_bc * a[hit, 2] + e_ca * b[hit, 2] + e_ab * c[hit, 2]) / (e_ab + e_bc + e_ca)
    return hit, z, normal_z[hit]


def _ragged(count):
    """(owner, local index) of every item when owner k has count[k] items."""
    owner = np.repeat(np.arange(len(count)), count)
    return owner, np.arange(int(count.sum())) - np.repeat(np.cumsum(count) - count, count)


def _column_pairs(vertices, triangles, origin, spacing, low, shape):
    """(triangle, column i, column j) for every lattice column within a triangle's
    xy bounding box, expanded without a loop."""
    corners = (vertices[triangles][:, :, :2] - origin[:2]) / spacing
    first = np.maximum(np.ceil(corners.min(axis=1)).astype(np.int64) - low[:2], 0)
    last = np.minimum(np.floor(corners.max(axis=1)).astype(np.int64) - low[:2],
                      np.array(shape[:2]) - 1)
    span = np.maximum(last - first + 1, 0)
    triangle, local = _ragged(span[:, 0] * span[:, 1])
    width = span[triangle, 1]
    i = first[triangle, 0] + local // np.maximum(width, 1)
    j = first[triangle, 1] + local % np.maximum(width, 1)
    return triangle, i, j


def fill_inside(vertices, triangles, spacing, origin=(0.0, 0.0, 0.0)):
    """The points of the lattice ``origin + spacing (i, j, k)`` inside the closed
    outward surface; shape (k, 3). Points on the surface itself fall either side.

    A vertical ray up each lattice column crosses triangles; each crossing adds
    the sign of the triangle's normal z to the winding number of every lattice
    point below it (leaving through an outward face counts +1). A column through
    an edge or a vertex is moved by an infinitesimal (:func:`_edge_side`), so it
    crosses exactly one of the triangles there. Cost: the columns under each
    triangle plus the lattice points.
    """
    origin = np.asarray(origin, dtype=float)
    low = np.ceil((vertices.min(axis=0) - origin) / spacing).astype(np.int64)
    high = np.floor((vertices.max(axis=0) - origin) / spacing).astype(np.int64)
    shape = tuple(int(n) for n in np.maximum(high - low + 1, 0))
    if min(shape) == 0:
        return np.empty((0, 3))
    triangle, i, j = _column_pairs(vertices, triangles, origin, spacing, low, shape)
    column = origin[:2] + spacing * np.column_stack([i + low[0], j + low[1]])
    hit, z, sign = _crossings(column, triangle, vertices, triangles)
    # Lattice levels strictly below the crossing: 0 .. below - 1.
    below = np.clip(np.ceil((z - origin[2]) / spacing - low[2]).astype(np.int64), 0, shape[2])
    flat = (i[hit] * shape[1] + j[hit]) * (shape[2] + 1) + below
    jumps = np.bincount(flat, weights=sign,
                        minlength=shape[0] * shape[1] * (shape[2] + 1))
    jumps = jumps.reshape(shape[0], shape[1], shape[2] + 1)
    # Winding number of level k: the crossings with below > k.
    winding = np.cumsum(jumps[:, :, ::-1], axis=2)[:, :, ::-1][:, :, 1:]
    inside = np.argwhere(winding > 0.5)
    return origin + spacing * (inside + low)


def points_inside(points, vertices, triangles):
    """Whether each point (k, 3) lies inside the closed outward surface; shape (k,).

    The ray test of :func:`fill_inside` for arbitrary points: triangles are binned
    by their xy bounding box on a grid of about the median edge, each point is
    tested against the triangles of its bin only, and the signs of the crossings
    above it add up to its winding number. Points on the surface fall either side.
    """
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    inside = np.zeros(len(points), bool)
    lower, upper = vertices.min(axis=0), vertices.max(axis=0)
    candidates = np.flatnonzero(np.all((points >= lower) & (points <= upper), axis=1))
    if not len(candidates) or not len(triangles):
        return inside
    size = float(np.median(edge_lengths(vertices, triangles)))
    bins = np.maximum(np.ceil((upper[:2] - lower[:2]) / size).astype(np.int64), 1)
    corners = (vertices[triangles][:, :, :2] - lower[:2]) / size
    first = np.clip(np.floor(corners.min(axis=1)).astype(np.int64), 0, bins - 1)
    last = np.clip(np.floor(corners.max(axis=1)).astype(np.int64), 0, bins - 1)
    span = last - first + 1
    triangle, local = _ragged(span[:, 0] * span[:, 1])
    cell = ((first[triangle, 0] + local // span[triangle, 1]) * bins[1]
            + first[triangle, 1] + local % span[triangle, 1])
    order = np.argsort(cell, kind="stable")
    triangle, per_cell = triangle[order], np.bincount(cell, minlength=bins.prod())
    start = np.cumsum(per_cell) - per_cell
    p = points[candidates]
    where = np.clip(np.floor((p[:, :2] - lower[:2]) / size).astype(np.int64), 0, bins - 1)
    own = where[:, 0] * bins[1] + where[:, 1]
    point, local = _ragged(per_cell[own])
    pairs = triangle[start[own[point]] + local]
    hit, z, sign = _crossings(p[point, :2], pairs, vertices, triangles)
    above = z > p[point[hit], 2]
    winding = np.bincount(point[hit][above], weights=sign[above], minlength=len(p))
    inside[candidates] = winding > 0.5
    return inside


# --------------------------------------------------------------------------
# The fluid beside a shell


def fluid_clearance(vertices, triangles, spacing):
    """How far from a shell's surface the fluid's lattice points are left out [m].

    The shell's nodes are particles of the fluid: each stands for a particle's volume
    l0^d. Leaving out the points within c of the surface, on both sides, removes a layer
    2 c thick, about 2 c A / l0^3 points on a surface of area A; it holds as many nodes as
    the layer held points when 2 c = l0^3 / a, a = A / nodes the mean area per node. On
    a mesh of edges l0 (a = (sqrt 3 / 2) l0^2) that is c = 0.58 l0. A finer mesh clears
    more, a coarser one no less than half a spacing (closer points overlap a node).
    """
    area = float(triangle_areas(vertices, triangles).sum())
    per_node = area / len(np.unique(triangles))
    return max(0.5 * spacing, 0.5 * spacing ** 3 / per_node)


# The longest mean edge, in particle spacings, of a shell in a fluid. Its nodes stand for
# the fluid they displace: at a mean edge of 1.41 l0 the capsule of cases/capsule_3d.toml
# has 114 nodes where the layer within half a spacing of it held 178 lattice points, and
# before the coupling held the water to its side it let 4 particles through there and 36 at
# 1.91 l0 (validation/capsule_3d/README.md).
MAX_EDGE_IN_FLUID = 1.25


def check_shell_in_fluid(label, vertices, triangles, spacing):
    """Refuse a shell whose nodes lie too far apart to hold the water, in one line."""
    mean = float(edge_lengths(vertices, triangles).mean())
    if mean > MAX_EDGE_IN_FLUID * spacing:
        raise CaseError(f"{label}: its mean edge {mean:.4g} m is {mean / spacing:.2f} "
                        f"particle spacings; in a fluid a shell's nodes are particles of "
                        f"it, standing for the water they displace, and must lie at most "
                        f"{MAX_EDGE_IN_FLUID} spacings apart on average: refine the shell "
                        f"(spacing or refinement)")


def displaced_by_shell(points, vertices, triangles, spacing):
    """Which of ``points`` (k, 3) lie within :func:`fluid_clearance` of the shell."""
    clearance = fluid_clearance(vertices, triangles, spacing)
    return surface_distance(points, vertices, triangles, clearance) < clearance


# --------------------------------------------------------------------------
# A shell body from its [[body]] table


SHAPES = ("sphere", "capsule", "red_blood_cell", "file")

# The [[body]] keys of type = "shell" (parmps.solids.settings adds them). A shell
# also reads spacing (target edge length), stiffness (edge springs), node_mass,
# damping, pinned, load and volume_constraint.
KEYS = {
    "shape": Key("str", "sphere", choices=SHAPES,
                 doc="shell: a generated sphere, capsule or red_blood_cell (Evans & Fung "
                     "1972), or a closed triangle mesh file"),
    "radius": Key("float", 0.0, ge=0.0, doc="shell sphere and capsule: radius [m]"),
    "length": Key("float", 0.0, ge=0.0,
                  doc="shell capsule: length of its cylinder [m] (total radius+length+radius)"),
    "diameter": Key("float", 0.0, ge=0.0,
                    doc="shell red_blood_cell: diameter [m]; 0 means Evans & Fung's 7.82 um"),
    "axis": Key("str", "z", choices=("x", "y", "z"),
                doc="shell capsule and red_blood_cell: the axis of symmetry"),
    "center": Key("vector", ZERO, doc="shell: centre of a generated shape; added to a mesh "
                                      "file's coordinates"),
    "mesh": Key("str", "", doc="shell with shape = \"file\": a closed surface mesh (STL, OBJ, "
                               "Gmsh .msh, VTK, ... read by meshio; a relative path is from "
                               "the working directory)"),
    "geodesic_base": Key("str", "octahedron", choices=("octahedron", "icosahedron"),
                         doc="shell red_blood_cell: the geodesic sphere mapped onto the cell "
                             "(the octahedron's grid runs along x and y; the icosahedron's "
                             "does not)"),
    "refinement": Key("int", 0, ge=0,
                      doc="shell: geodesic frequency n (each base edge cut n times; 2^k is k "
                          "midpoint subdivisions) instead of spacing"),
    "bending_stiffness": Key("float", 0.0, ge=0.0,
                             doc="shell: spring joining the two vertices opposite each edge "
                                 "[N/m]; 0: no bending springs"),
    "surface_density": Key("float", 0.0, ge=0.0,
                           doc="shell: mass per area [kg/m^2]; a node gets a third of its "
                               "triangles' area (instead of node_mass)"),
}

# Keys of the other body types, refused on a shell.
OTHER_KEYS = {"nx": 0, "ny": 0, "nz": 0, "density": 0.0, "shear_stiffness": 0.0,
              "youngs_modulus": 0.0, "nodes": [], "springs": [], "boundary": [],
              "masses": [], "spring_stiffness": [], "anchors": [], "poisson_ratio": None,
              "damping_ratio": 0.0, "plane": "strain", "thickness": 1.0}


def check_keys(label, spec):
    """Refuse shell keys on another body type, and other types' keys on a shell."""
    if spec["type"] == "shell":
        for key, unset in OTHER_KEYS.items():
            if spec.get(key, unset) != unset:
                raise CaseError(f"{label}.{key} does not apply to a shell body")
        return
    for key, value in KEYS.items():
        if key in spec and spec[key] != (value.default(len(spec["center"]))
                                         if callable(value.default) else value.default):
            raise CaseError(f"{label}.{key} applies to shell bodies only (type = \"shell\")")


def _oriented(mesh, axis, center):
    """A mesh made along z turned to ``axis`` by a cyclic permutation (a rotation,
    so the triangles stay outward), then moved to ``center``."""
    vertices, triangles = mesh
    turn = {"z": [0, 1, 2], "x": [2, 0, 1], "y": [1, 2, 0]}[axis]
    return vertices[:, turn] + np.asarray(center, dtype=float), triangles


# The keys each shape reads, beside center; the others must keep their defaults.
SHAPE_KEYS = {"sphere": ("radius", "spacing", "refinement"),
              "capsule": ("radius", "length", "axis", "spacing", "refinement"),
              "red_blood_cell": ("diameter", "axis", "spacing", "refinement", "geodesic_base"),
              "file": ("mesh",)}
UNSET = {"radius": 0.0, "length": 0.0, "diameter": 0.0, "axis": "z", "mesh": "",
         "spacing": 0.0, "refinement": 0, "geodesic_base": "octahedron"}


def _check_shape_keys(label, spec):
    shape = spec["shape"]
    for key, unset in UNSET.items():
        if spec[key] != unset and key not in SHAPE_KEYS[shape]:
            raise CaseError(f"{label}.{key} does not apply to shape = \"{shape}\" (it reads "
                            f"{', '.join(SHAPE_KEYS[shape])} and center)")
    if spec["spacing"] and spec["refinement"]:
        raise CaseError(f"{label}: give spacing (a target edge length) or refinement, not both")


def shell_mesh(label, spec):
    """(vertices, triangles) of a ``type = "shell"`` body, checked; ``label`` names
    the body in messages."""
    _check_shape_keys(label, spec)
    shape, h = spec["shape"], spec["spacing"] or None
    frequency = spec["refinement"] or None
    if shape == "file":
        if not spec["mesh"]:
            raise CaseError(f"{label}: shape = \"file\" needs mesh = \"path\" (STL, OBJ, "
                            f"Gmsh .msh, VTK, ...)")
        source = f"{label}.mesh '{spec['mesh']}'"
        vertices, triangles = read_mesh(spec["mesh"], source)
        mesh = (vertices + np.asarray(spec["center"], dtype=float), triangles)
    else:
        if shape in ("sphere", "capsule") and not spec["radius"] > 0:
            raise CaseError(f"{label}.radius must be > 0 for shape = \"{shape}\"")
        try:
            if shape == "sphere":
                made = icosphere(spec["radius"], frequency, h)
            elif shape == "capsule":
                made = capsule(spec["radius"], spec["length"], h, frequency)
            else:
                made = red_blood_cell(spec["diameter"] or RBC_DIAMETER, h, frequency,
                                      base=spec.get("geodesic_base", "octahedron"))
        except CaseError as exc:  # the generators name themselves, not the body
            raise CaseError(f"{label}: {exc}") from None
        mesh = _oriented(made, spec["axis"], spec["center"])
        source = f"{label} ({shape} generator)"
    check_closed_surface(source, *mesh)
    return mesh


def shell_body(label, spec, dimension):
    """What build.py needs of a shell: (position, springs, stiffness, mass, facets, None).

    Springs: every edge (``stiffness``), then, with ``bending_stiffness``, one across
    every edge between the vertices opposite it. The facets are the triangles.
    """
    if dimension != 3:
        raise CaseError(f"{label}.type = \"shell\" is a closed surface in 3D; this case is "
                        f"{dimension}D")
    check_keys(label, spec)
    vertices, triangles = shell_mesh(label, spec)
    edges, bending = edges_and_bending(triangles)
    if spec["stiffness"] is None:
        raise CaseError(f"{label}: missing key 'stiffness' [N/m] (the edge springs)")
    springs, stiffness = edges, np.full(len(edges), spec["stiffness"])
    if spec["bending_stiffness"] > 0:
        springs = np.concatenate([edges, bending])
        stiffness = np.concatenate([stiffness, np.full(len(bending),
                                                       spec["bending_stiffness"])])
    if spec["node_mass"] > 0 and spec["surface_density"] > 0:
        raise CaseError(f"{label}: give node_mass or surface_density, not both")
    if spec["node_mass"] > 0:
        mass = np.full(len(vertices), spec["node_mass"])
    elif spec["surface_density"] > 0:
        mass = spec["surface_density"] * node_areas(vertices, triangles)
    else:
        raise CaseError(f"{label}: node mass must be > 0: set node_mass [kg] or "
                        f"surface_density [kg/m^2]")
    log.debug("%s: %d nodes, %d triangles, %d springs (%d bending), volume %.6g", label,
             len(vertices), len(triangles), len(springs), len(springs) - len(edges),
             enclosed_volume(vertices, triangles))
    return vertices, springs, stiffness, mass, triangles, None
