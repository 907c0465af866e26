"""The XDMF sidecar of result.h5: what ParaView opens.

Temporal collections: ``particles``, one point cloud per frame with every
particle array; for a case with bodies ``springs``, every body's springs as
2-node polylines at the same times, so ParaView draws the bodies' meshes; and
for bodies whose boundary is triangles (3D) ``surfaces``, those triangles, so
ParaView draws the surface whose volume the constraint keeps. (A 2D body's
boundary edges are springs already drawn.)
The file is rewritten whole after each frame through a temporary file, so a
run that stops at any moment leaves a sidecar that names only written frames.
"""

import os

GEOMETRY_TYPES = {2: "XY", 3: "XYZ"}


def _particle_grid(h5_name, step, time, total, n_vertex_index, dimension):
    """One frame's particles. Each particle is one Polyvertex cell, so ParaView's default
    Surface view draws them: the connectivity is the first ``total`` entries of
    ``/vertex_index`` (``n_vertex_index`` long), cut by a HyperSlab. The XDMF3 reader
    makes no cells from a Polyvertex without connectivity, and the legacy XDMF reader
    crashes on an HDF item shorter than its dataset."""
    base = f"{h5_name}:/frames/{step:08d}"

    def item(name, dims, number="Float", precision=8):
        return (f'<DataItem Dimensions="{dims}" NumberType="{number}" '
                f'Precision="{precision}" Format="HDF">{base}/{name}</DataItem>')

    if total:
        topology = f"""<Topology TopologyType="Polyvertex" NumberOfElements="{total}" NodesPerElement="1">
          <DataItem ItemType="HyperSlab" Dimensions="{total}" Type="HyperSlab">
            <DataItem Dimensions="3 1" NumberType="Int" Format="XML">0 1 {total}</DataItem>
            <DataItem Dimensions="{n_vertex_index}" NumberType="Int" Precision="8" Format="HDF">{h5_name}:/vertex_index</DataItem>
          </DataItem>
        </Topology>"""
    else:
        topology = '<Topology TopologyType="Polyvertex" NumberOfElements="0" NodesPerElement="1"/>'
    d = dimension
    return f"""      <Grid Name="step {step}" GridType="Uniform">
        <Time Value="{time:.10g}"/>
        {topology}
        <Geometry GeometryType="{GEOMETRY_TYPES[d]}">{item("position", f"{total} {d}")}</Geometry>
        <Attribute Name="pressure" AttributeType="Scalar" Center="Node">{item("pressure", total)}</Attribute>
        <Attribute Name="velocity" AttributeType="Vector" Center="Node">{item("velocity", f"{total} {d}")}</Attribute>
        <Attribute Name="number_density" AttributeType="Scalar" Center="Node">{item("number_density", total)}</Attribute>
        <Attribute Name="kind" AttributeType="Scalar" Center="Node">{item("kind", total, "Char", 1)}</Attribute>
        <Attribute Name="id" AttributeType="Scalar" Center="Node">{item("id", total, "Int", 8)}</Attribute>
      </Grid>"""


def _body_collection(h5_name, frames, bodies, dimension, mesh):
    """Every body's springs (``mesh`` = "springs": 2-node polylines) or surface triangles
    (``mesh`` = "surface"), one spatial collection per frame.

    ``bodies``: (name, nodes, elements, nodes per element) per body.
    """
    d = dimension
    topology = {"springs": "Polyline", "surface": "Triangle"}[mesh]
    steps = []
    for step, time, _ in frames:
        grids = []
        for name, n_nodes, count, width in bodies:
            base = f"{h5_name}:/frames/{step:08d}/solids/{name}"
            grids.append(f"""          <Grid Name="{name}" GridType="Uniform">
            <Topology TopologyType="{topology}" NumberOfElements="{count}" NodesPerElement="{width}">
              <DataItem Dimensions="{count} {width}" NumberType="Int" Precision="8" Format="HDF">{h5_name}:/solids/{name}/{mesh}</DataItem>
            </Topology>
            <Geometry GeometryType="{GEOMETRY_TYPES[d]}">
              <DataItem Dimensions="{n_nodes} {d}" NumberType="Float" Precision="8" Format="HDF">{base}/position</DataItem>
            </Geometry>
            <Attribute Name="velocity" AttributeType="Vector" Center="Node">
              <DataItem Dimensions="{n_nodes} {d}" NumberType="Float" Precision="8" Format="HDF">{base}/velocity</DataItem>
            </Attribute>
          </Grid>""")
        steps.append(f"""      <Grid Name="{mesh} step {step}" GridType="Collection" CollectionType="Spatial">
        <Time Value="{time:.10g}"/>
""" + "\n".join(grids) + """
      </Grid>""")
    name = {"springs": "springs", "surface": "surfaces"}[mesh]
    return (f"""    <Grid Name="{name}" GridType="Collection" CollectionType="Temporal">
""" + "\n".join(steps) + """
    </Grid>
""")


def write_xdmf(path, h5_name, frames, n_vertex_index, dimension=2, bodies=()):
    """Write the sidecar for ``frames`` ((step, time, particle count) each) and ``bodies``
    ((name, nodes, springs, surface shape) each); ``n_vertex_index``: the length of
    ``/vertex_index``."""
    springs = [(name, nodes, count, 2) for name, nodes, count, _ in bodies]
    # Triangles only: a 2D boundary's edges are springs, drawn already.
    surfaces = [(name, nodes, shape[0], 3) for name, nodes, _, shape in bodies
                if shape[1:] == (3,)]
    grids = [_particle_grid(h5_name, step, time, total, n_vertex_index, dimension)
             for step, time, total in frames]
    text = ("""<?xml version="1.0" ?>
<!DOCTYPE Xdmf SYSTEM "Xdmf.dtd" []>
<Xdmf Version="2.0">
  <Domain>
    <Grid Name="particles" GridType="Collection" CollectionType="Temporal">
""" + "\n".join(grids) + """
    </Grid>
""" + (_body_collection(h5_name, frames, springs, dimension, "springs") if springs else "")
            + (_body_collection(h5_name, frames, surfaces, dimension, "surface")
               if surfaces else "") + """  </Domain>
</Xdmf>
""")
    temporary = path + ".tmp"
    with open(temporary, "w") as handle:
        handle.write(text)
    os.replace(temporary, path)
