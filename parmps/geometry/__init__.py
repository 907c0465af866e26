"""The geometry of a case, with one owner: the domain, the walls of every shape, the
fluid's shapes, surface meshes and the scene builder.

- :mod:`parmps.geometry.mesh`: triangle surfaces (read through meshio, merged,
  checked closed and oriented, inside tests, enclosed volume).
- :mod:`parmps.geometry.shapes`: generated closed surfaces (sphere, capsule, red
  blood cell).
- :mod:`parmps.geometry.scene`: the case's blocks, tanks, wall boxes and walls as
  particles on the lattice.

Everything else receives objects from here; nothing this package imports (the core,
the errors, the configuration machinery) imports it.
"""
