"""Triangle surfaces: the `Mesh`, its volume and gradient, and sphere generators.

A `Mesh` is an immutable, validated triangle surface (counter-clockwise faces
seen from outside) with the ordered one-ring fans the force kernels need.
The package's rooms:

- `surface`: the `Mesh` class (construction, loading, immutability, geometry);
- `geometry`: volume, its gradient, vertex areas and the row-wise helpers, on plain arrays;
- `validate`: the checks of a surface and the building of its edges and fans;
- `hulls`: the convex hull's triangles of points on a sphere, cached on disk;
- `spheres`: `uv_sphere` (the paper's 80-point body), `icosahedron`, `icosphere`, `irregular_sphere`,
  `fibonacci_sphere` and `ring_sphere` (pole-free, any size), `level_counts` (the mesh levels).
"""

from __future__ import annotations

from .geometry import vertex_area, volume, volume_gradient
from .spheres import (
    ICOSPHERE_MAX_SUBDIVISIONS,
    MAX_LEVEL,
    fibonacci_sphere,
    icosahedron,
    icosphere,
    irregular_sphere,
    level_counts,
    ring_sphere,
    uv_sphere,
)
from .surface import LOAD_SUFFIXES, Mesh

__all__ = [
    "Mesh",
    "uv_sphere",
    "icosahedron",
    "icosphere",
    "irregular_sphere",
    "fibonacci_sphere",
    "ring_sphere",
    "level_counts",
    "MAX_LEVEL",
    "volume",
    "volume_gradient",
    "vertex_area",
    "LOAD_SUFFIXES",
    "ICOSPHERE_MAX_SUBDIVISIONS",
]
