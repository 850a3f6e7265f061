"""Geometry in numpy only: meshes in, checks, primitives, tetrahedralization, topology, mass."""
