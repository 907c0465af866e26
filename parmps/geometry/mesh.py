"""Triangle surface meshes: reading, merging, measures, checks, inside tests, volume.

A closed surface is a set of outward facets: in 3D triangles (m, 3) of vertices
(n, 3) whose normal (x_b - x_a) x (x_c - x_a) points out, in 2D the edges of a
counter-clockwise loop. Arrays in, arrays out, no Python loop over triangles.

- :func:`read_mesh` reads a file through meshio and merges duplicate vertices
  (STL stores each triangle's corners separately).
- :func:`check_closed_surface` refuses a mesh that is not a closed, consistently
  and outward oriented, manifold surface, in one line naming its source.
- :func:`points_inside` / :func:`fill_inside` the lattice points inside the
  surface, :func:`enclosed_volume` the volume (area in 2D) it encloses.
- :func:`edges_and_bending` the edges and the vertices opposite each (the shells'
  springs).
"""

import logging
import math
from itertools import permutations

import numpy as np

from parmps.errors import CaseError

log = logging.getLogger(__name__)

# Duplicate vertices of a file closer than this share of the median edge are one.
MERGE_TOLERANCE = 1e-5

# A triangle with less than this share of the median edge squared has no area.
DEGENERATE_AREA = 1e-10


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


def _check_cells(source, vertices, triangles, closed=True):
    """Indices in range, no unused vertex, no triangle without area (``closed``: and
    enough triangles to close a surface)."""
    n = len(vertices)
    if not len(triangles):
        raise CaseError(f"{source}: the mesh has no triangles")
    if closed and len(triangles) < 4:
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


def _check_edges(source, vertices, triangles, allow_open=False):
    """Every edge on exactly two triangles (``allow_open``: or on one, an edge of the
    surface's rim), which run along it in opposite directions. Returns the open edges'
    count."""
    start, end, _ = _half_edges(triangles)
    order, first, counts = _edge_groups(start, end)
    a, b = start[order[first]], end[order[first]]

    def example(mask):
        e = int(np.flatnonzero(mask)[0])
        i, j = sorted((int(a[e]), int(b[e])))
        return f"e.g. the edge between vertices {i} and {j} at {_at(vertices, i)}"

    open_edges = counts == 1
    if open_edges.any() and not allow_open:
        raise CaseError(f"{source}: the surface is not closed: {int(open_edges.sum())} open "
                        f"edges (on one triangle only), {example(open_edges)}")
    shared = counts > 2
    if shared.any():
        raise CaseError(f"{source}: {int(shared.sum())} non-manifold edges (on more than two "
                        f"triangles), {example(shared)}")
    # An edge that both its triangles run along in the same direction has the same
    # start as its partner.
    paired = first[counts == 2]
    same = np.zeros(len(first), bool)
    same[counts == 2] = start[order[paired]] == start[order[paired + 1]]
    if same.any():
        raise CaseError(f"{source}: inconsistent orientation: {int(same.sum())} edges run the "
                        f"same way in both their triangles, {example(same)}; orient every "
                        f"triangle outward")
    return int(open_edges.sum())


def check_closed_surface(source, vertices, triangles, single=True):
    """Refuse, in one line starting with ``source``, a mesh that is not a closed,
    manifold, consistently and outward oriented surface (``single``: and one connected
    surface, as a shell body is; a wall may be several). Returns its volume."""
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
    if single and len(parts) > 1:
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


def check_wall_surface(source, vertices, triangles):
    """Refuse, in one line starting with ``source``, a wall's mesh that is not a manifold,
    consistently oriented surface; a closed one must also face outward (as
    :func:`check_closed_surface`). Returns whether the surface is open (has a rim): an
    open wall's fluid lies on the side its triangles face."""
    vertices = np.asarray(vertices, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    _check_cells(source, vertices, triangles, closed=False)
    if _check_edges(source, vertices, triangles, allow_open=True) == 0:
        check_closed_surface(source, vertices, triangles, single=False)
        return False
    return True


def check_polyline(source, vertices, segments):
    """Refuse, in one line starting with ``source``, a 2D wall's curve that is not a
    consistently oriented, manifold polyline (each vertex starting at most one segment and
    ending at most one, no segment without length); a closed one must run counter-clockwise
    (its segments' right-hand sides facing out). Returns whether it is open (has ends)."""
    vertices = np.asarray(vertices, dtype=float)
    segments = np.asarray(segments, dtype=np.int64)
    if not len(segments):
        raise CaseError(f"{source}: the mesh has no line segments")
    length = np.linalg.norm(vertices[segments[:, 1]] - vertices[segments[:, 0]], axis=1)
    if np.any(length <= 1e-12 * float(np.ptp(vertices, axis=0).max())):
        k = int(np.argmin(length))
        raise CaseError(f"{source}: segment {k} has no length (vertices "
                        f"{segments[k, 0]} and {segments[k, 1]})")
    starts = np.bincount(segments[:, 0], minlength=len(vertices))
    ends = np.bincount(segments[:, 1], minlength=len(vertices))
    for count, what in ((starts, "start"), (ends, "end")):
        if count.max() > 1:
            v = int(np.argmax(count))
            raise CaseError(f"{source}: inconsistent orientation or a branch: {int(count[v])} "
                            f"segments {what} at vertex {v} ({vertices[v, 0]:.6g}, "
                            f"{vertices[v, 1]:.6g}); each vertex starts one segment and ends "
                            f"one")
    if np.any(starts + ends == 0):
        raise CaseError(f"{source}: {int(np.sum(starts + ends == 0))} unused vertices (on no "
                        f"segment); remove them")
    is_open = bool(np.any(starts != ends))
    if not is_open and enclosed_volume(vertices, segments) < 0:
        raise CaseError(f"{source}: the closed curve runs clockwise (its area "
                        f"{enclosed_volume(vertices, segments):.6g}); reverse its segments: "
                        f"parmps refuses rather than reorder them")
    return is_open


def _meshio_read(path, source):
    """The file read by meshio; what it cannot read is bad input, in one line."""
    import meshio  # only meshes read files: a case without one does not import it

    try:
        return meshio.read(path)
    # meshio reports unreadable files with many exception types; each is bad input.
    except Exception as exc:  # noqa: BLE001
        raise CaseError(f"{source}: cannot be read: "
                        f"{str(exc).splitlines()[0] if str(exc) else type(exc).__name__}"
                        ) from None


def read_polyline(path, source=None):
    """Vertices (n, 2) and line segments (m, 2) of a 2D curve in a mesh file meshio reads
    (Gmsh, VTK, ...: its ``line`` cells), its points in one plane z = constant; duplicates
    merged within MERGE_TOLERANCE of the median segment. Not checked: :func:`check_polyline`."""
    source = source or f"mesh '{path}'"
    mesh = _meshio_read(path, source)
    points = np.asarray(mesh.points, dtype=float)
    if points.shape[1] == 3:
        if np.ptp(points[:, 2]) > 1e-9 * max(float(np.ptp(points[:, :2], axis=0).max()), 1e-300):
            raise CaseError(f"{source}: a 2D wall's curve lies in a plane z = constant; its "
                            f"points span z in [{points[:, 2].min():.6g}, "
                            f"{points[:, 2].max():.6g}]")
        points = points[:, :2]
    lines = [block.data for block in mesh.cells if block.type == "line"]
    if not lines:
        kinds = ", ".join(sorted({block.type for block in mesh.cells})) or "none"
        raise CaseError(f"{source}: no line segments (cells: {kinds}); a 2D wall is a curve "
                        f"of line cells")
    segments = np.concatenate(lines).astype(np.int64)
    if segments.min() < 0 or segments.max() >= len(points):
        raise CaseError(f"{source}: a cell names a point the file does not have")
    unused = len(points) - len(np.unique(segments))
    if unused:
        raise CaseError(f"{source}: {unused} unused points (on no segment); remove them")
    scale = float(np.median(np.linalg.norm(points[segments[:, 1]] - points[segments[:, 0]],
                                           axis=1)))
    if not scale > 0:
        raise CaseError(f"{source}: the segments have no length (median 0)")
    # merge_vertices bins in 3D: the plane's points at z = 0.
    flat = np.column_stack([points, np.zeros(len(points))])
    vertices, segments = merge_vertices(flat, segments, MERGE_TOLERANCE * scale)
    return vertices[:, :2], segments


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
    source = source or f"mesh '{path}'"
    mesh = _meshio_read(path, source)
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
    outward surface; shape (k, 3). Points on the surface itself fall either side
    (:func:`lattice_winding`)."""
    origin = np.asarray(origin, dtype=float)
    low = np.ceil((vertices.min(axis=0) - origin) / spacing).astype(np.int64)
    high = np.floor((vertices.max(axis=0) - origin) / spacing).astype(np.int64)
    shape = tuple(int(n) for n in np.maximum(high - low + 1, 0))
    if min(shape) == 0:
        return np.empty((0, 3))
    winding = lattice_winding(vertices, triangles, spacing, origin, low, shape)
    inside = np.argwhere(winding > 0.5)
    return origin + spacing * (inside + low)


def lattice_winding(vertices, triangles, spacing, origin, low, shape):
    """The winding number (shape ``shape``) of the closed outward surface at the lattice
    points ``origin + spacing (low + (i, j, k))``: 1 inside, 0 outside.

    A vertical ray up each lattice column crosses triangles; each crossing adds
    the sign of the triangle's normal z to the winding number of every lattice
    point below it (leaving through an outward face counts +1). A column through
    an edge or a vertex is moved by an infinitesimal (:func:`_edge_side`), so it
    crosses exactly one of the triangles there. Cost: the columns under each
    triangle plus the lattice points.
    """
    origin = np.asarray(origin, dtype=float)
    low = np.asarray(low, dtype=np.int64)
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
    return np.cumsum(jumps[:, :, ::-1], axis=2)[:, :, ::-1][:, :, 1:]


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
# Volume


def _permutations(d):
    """Every permutation of range(d) with its sign: the terms of a d x d determinant."""
    out = []
    for p in permutations(range(d)):
        inversions = sum(p[a] > p[b] for a in range(d) for b in range(a + 1, d))
        out.append((p, -1.0 if inversions % 2 else 1.0))
    return out


def determinant_terms(d):
    """(permutations (d!, d) int64, signs (d!,), d!) as arrays, for the compiled
    kernels.facet_volume."""
    terms = _permutations(d)
    return (np.array([p for p, _ in terms], dtype=np.int64),
            np.array([sign for _, sign in terms]), float(math.factorial(d)))


def _corners(position, facets):
    """(m, d, d) facet corner positions about the apex: [facet, corner, component]."""
    position = np.asarray(position, dtype=float)
    facets = np.asarray(facets, dtype=np.int64)
    apex = position[facets[0, 0]] if len(facets) else 0.0
    return position[facets] - apex


def enclosed_volume(position, facets):
    """V = 1/d! sum det[x_a; x_b; ...] over ``facets`` (m, d) of ``position`` (n, d).

    Positive when the facets face outward; the area in 2D.
    """
    # Summed before the division by d!, as before the moments shared it: a lattice's volume
    # stays exact (tests/test_solid_3d.py).
    x = _corners(position, facets)
    return float(_determinants(x).sum()) / math.factorial(x.shape[-1])


def _determinants(x):
    """det[x_a; x_b; ...] of each facet's simplex with the apex, (m,): d! its volume."""
    d = x.shape[-1]
    determinant = np.zeros(len(x))
    for p, sign in _permutations(d):
        term = sign * x[:, 0, p[0]]
        for r in range(1, d):
            term = term * x[:, r, p[r]]
        determinant += term
    return determinant


def enclosed_moments(position, facets):
    """(V, centroid (d,), M (d, d)) of the region ``facets`` enclose: its volume, its
    centre and its second moment M = int (x - c)(x - c)^T dV about that centre.

    Each facet's signed simplex with the apex adds its own moments; a simplex of
    volume v with corners y_0..y_d has int y y^T = v/((d+1)(d+2)) (sum y_a y_a^T +
    (sum y_a)(sum y_a)^T) (the apex is y_0 = 0 here). An ellipsoid of semi-axes a_k
    has eigenvalues V a_k^2 / (d + 2): the shape of a deformed capsule.
    """
    x = _corners(position, facets)
    m, d = len(x), position.shape[1]
    if m == 0:
        return 0.0, np.zeros(d), np.zeros((d, d))
    apex = np.asarray(position, dtype=float)[np.asarray(facets)[0, 0]]
    v = _determinants(x) / math.factorial(d)
    volume = float(v.sum())
    # The simplex's centre is the mean of its d + 1 corners, the apex among them.
    first = (v[:, None] * x.sum(axis=1)).sum(axis=0) / (d + 1)
    total = x.sum(axis=1)
    second = (np.einsum("m,mai,maj->ij", v, x, x) + np.einsum("m,mi,mj->ij", v, total, total))
    second /= (d + 1) * (d + 2)
    centre = first / volume
    moment = second - volume * np.outer(centre, centre)
    return volume, apex + centre, moment
