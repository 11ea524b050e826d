"""The `Mesh`: an immutable, validated triangle surface with its one-ring fans.

A `Mesh` holds the topology and rest geometry of a membrane: mass points
(`vert_pos`, m) on a triangle surface (`face_vert`, counter-clockwise seen
from outside, so that face normals point outward). It is validated once, when
it is built (`hybrid.mesh.validate`), and is immutable afterwards: every
array is read-only.

Beyond the faces, a mesh stores what the force and constraint kernels need:

- the ordered one-ring of every vertex (paper section 3.4, the neighbours
  N_1 .. N_eta of a point), in CSR form `ring_ptr` / `ring_vert`: each
  consecutive pair (N_j, N_j+1) spans a face (a, N_j, N_j+1) of the mesh, i.e.
  the ring turns counter-clockwise around the outward normal. A closed fan
  starts at its smallest neighbour index and wraps (N_eta, N_1 is a face too);
  an open (border) fan runs from one border neighbour to the other;
- the unique undirected edges `edge_vert` and the border vertices.

Files are read through trimesh, imported only when needed (OBJ files by
`hybrid.mesh.obj`, which keeps their vertex order).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from hybrid.errors import MeshError

from .geometry import cross_rows, scatter_corners, volume, volume_gradient
from .obj import read_obj
from .validate import (
    FEW,
    border_edges,
    check_face_vert,
    check_vert_pos,
    few,
    merge_identical_vertices,
    validate_and_build,
)

if TYPE_CHECKING:  # trimesh is imported only when a file is loaded or exported
    import trimesh

__all__ = ["Mesh", "LOAD_SUFFIXES"]

#: file suffixes `Mesh.load` accepts (read by trimesh)
LOAD_SUFFIXES = (".stl", ".obj", ".ply", ".off")


#: bytes of a binary STL's header and of each of its triangles
_STL_HEAD, _STL_TRIANGLE = 84, 50
#: the fewest bytes a point takes in a text mesh file: "v 0 0 0" and its two triangles ("f 1 2 3")
_TEXT_BYTES_PER_POINT = 24


def _check_file_size(path: Path, suffix: str) -> None:
    """The points a mesh file can hold, checked before it is read (`checks.mesh_points`):
    a binary STL by the triangle count in its header, which must match its size; a
    text file by its size."""
    from ..checks import mesh_points

    size = path.stat().st_size
    if suffix == ".stl":
        with open(path, "rb") as f:
            head = f.read(_STL_HEAD)
        count = int.from_bytes(head[80:84], "little") if len(head) == _STL_HEAD else -1
        if count >= 0 and not head.lstrip().lower().startswith(b"solid"):  # binary
            if size != _STL_HEAD + _STL_TRIANGLE * count:
                raise MeshError(
                    f"mesh file {str(path)!r}: a binary STL whose header claims {count:,} triangles "
                    f"({_STL_HEAD + _STL_TRIANGLE * count:,} bytes); expected that size, received {size:,} bytes"
                )
            # a closed surface of F triangles has F / 2 + 2 points (shared after merging)
            mesh_points(f"mesh file {str(path)!r}", count // 2 + 2, f"{count:,} triangles give about ", error=MeshError)
            return
    mesh_points(
        f"mesh file {str(path)!r}",
        size // _TEXT_BYTES_PER_POINT,
        f"{size:,} bytes may hold up to ",
        error=MeshError,
    )


class Mesh:
    """An immutable, validated triangle surface with its one-ring fans.

    Attributes (all arrays read-only)
    ----------
    vert_pos : (nvert, 3) float64, m       rest positions, C-contiguous
    face_vert : (nface, 3) int32           corners, counter-clockwise seen from outside
    nvert, nface : int
    closed : bool                          every edge is shared by exactly two faces
    ring_ptr : (nvert + 1,) int32          CSR offsets into ring_vert
    ring_vert : (ring_ptr[-1],) int32      ordered one-ring of each vertex (see module doc)
    ring_closed : (nvert,) bool            False for border vertices (open fan)
    edge_vert : (nedge, 2) int32           unique undirected edges, i < j, lexicographic order
    border_vert : (nborder,) int32         sorted border vertices (empty if closed)
    name : str

    Build one with `Mesh.from_arrays`, `Mesh.load`, `uv_sphere`, `icosahedron`
    or `icosphere`; every one of them validates (see `from_arrays`).
    """

    __slots__ = (
        "vert_pos",
        "face_vert",
        "nvert",
        "nface",
        "closed",
        "ring_ptr",
        "ring_vert",
        "ring_closed",
        "edge_vert",
        "border_vert",
        "name",
        "refinement",
    )
    # the slots' types (annotations only: no class attribute, so no clash with __slots__)
    vert_pos: np.ndarray
    face_vert: np.ndarray
    nvert: int
    nface: int
    closed: bool
    ring_ptr: np.ndarray
    ring_vert: np.ndarray
    ring_closed: np.ndarray
    edge_vert: np.ndarray
    border_vert: np.ndarray
    name: str
    refinement: object  # hybrid.mesh.refine.Refinement of a mesh refined from a coarser one, or None

    def __init__(self, vert_pos, face_vert, *, name: str = "mesh", refinement=None):
        name = str(name)
        pos = check_vert_pos(vert_pos, name)
        face = check_face_vert(face_vert, len(pos), name)
        topo = validate_and_build(pos, face, name)
        fields = dict(
            vert_pos=pos,
            face_vert=face,
            nvert=len(pos),
            nface=len(face),
            name=name,
            refinement=refinement,
            **topo,
        )
        for key, value in fields.items():
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
            object.__setattr__(self, key, value)

    # -- construction -------------------------------------------------------

    @classmethod
    def from_arrays(cls, vert_pos, face_vert, *, name: str = "mesh", refinement=None) -> Mesh:
        """Validate arrays and build a mesh (the arrays are copied).

        vert_pos (nvert, 3) real, m; face_vert (nface, 3) int in [0, nvert),
        counter-clockwise seen from outside. Raises `MeshError`, naming the
        faulty faces or vertices, for: wrong shapes or types, non-finite
        coordinates, out-of-range indices, degenerate faces (a repeated index,
        or area < 1e-14 * mean edge length^2), duplicate faces (same vertex
        set in any order), duplicate vertices (identical coordinates), unused
        vertices, non-manifold edges (> 2 faces), inconsistent orientation
        (an edge used twice in the same direction), non-manifold vertices
        (incident faces not a single fan) and closed surfaces that face
        inward (negative volume). Open surfaces are allowed; see
        `require_closed`. `refinement`: how the mesh was refined from a coarser one
        (`hybrid.mesh.refine.Refinement`), for regions given on the coarse mesh's points.
        """
        return cls(vert_pos, face_vert, name=name, refinement=refinement)

    @classmethod
    def load(cls, path, *, name: str | None = None) -> Mesh:
        """Read a mesh file (STL, OBJ, PLY or OFF) with trimesh and validate it.

        Vertex k of the file is vertex k of the mesh: OBJ files are read by
        `hybrid.mesh.obj.read_obj` (trimesh's reader drops unused vertices and
        renumbers the rest), PLY, OFF and STL by
        `trimesh.load(path, process=False, force="mesh")`, which keeps them.
        A vertex in no face is refused, never dropped. STL stores each triangle's corners
        separately (no shared vertices), so for STL files exactly identical
        vertices are merged first (kept in order of first appearance); any
        other format must already share its vertices. `name` defaults to the
        file stem. Raises `MeshError` naming the path if the file is missing,
        has an unsupported suffix or cannot be read.
        """
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix not in LOAD_SUFFIXES:
            raise MeshError(
                f"mesh file {str(path)!r}: unsupported suffix {path.suffix!r}; "
                f"expected one of {', '.join(LOAD_SUFFIXES)}"
            )
        if not path.is_file():
            raise MeshError(f"mesh file {str(path)!r} does not exist or is not a file")
        _check_file_size(path, suffix)
        if suffix == ".obj":
            vert_pos, face_vert = read_obj(str(path))
        else:
            import trimesh

            try:
                loaded = trimesh.load(str(path), process=False, force="mesh")
                vert_pos = np.asarray(loaded.vertices, dtype=np.float64)
                face_vert = np.asarray(loaded.faces, dtype=np.int64).reshape(-1, 3)
            except Exception as exc:  # trimesh raises many types on bad input
                raise MeshError(
                    f"mesh file {str(path)!r} cannot be read as a triangle mesh: {type(exc).__name__}: {exc}"
                ) from exc
        if suffix == ".stl":
            vert_pos, face_vert = merge_identical_vertices(vert_pos, face_vert)
        if name is None:
            name = path.stem
        try:
            return cls(vert_pos, face_vert, name=name)
        except MeshError as exc:
            raise MeshError(f"mesh file {str(path)!r}: {exc}") from None

    def save(self, path) -> None:
        """Write the surface to an OBJ file (`hybrid.mesh.obj.write_obj`): vertex k
        stays vertex k and every position reads back to the same double."""
        from .obj import write_obj

        path = Path(path)
        if path.suffix.lower() != ".obj":
            raise MeshError(
                f"mesh file {str(path)!r}: expected a .obj path to save to, received suffix {path.suffix!r}"
            )
        write_obj(path, self.vert_pos, self.face_vert)

    # -- immutability -------------------------------------------------------

    def __setattr__(self, key, value):
        raise AttributeError(f"Mesh is immutable: cannot set {key!r}; build a new Mesh")

    def __delattr__(self, key):
        raise AttributeError(f"Mesh is immutable: cannot delete {key!r}")

    def __reduce__(self):
        # __slots__ + a blocking __setattr__ defeat the default pickling; rebuild instead.
        return (_rebuild_mesh, (np.array(self.vert_pos), np.array(self.face_vert), self.name, self.refinement))

    def __repr__(self) -> str:
        kind = "closed" if self.closed else f"open, {len(self.border_vert)} border vertices"
        return f"Mesh({self.name!r}, nvert={self.nvert}, nface={self.nface}, {kind})"

    # -- geometry -----------------------------------------------------------

    def _pos(self, vert_pos) -> np.ndarray:
        """The rest positions, or `vert_pos` checked to be (nvert, 3)."""
        if vert_pos is None:
            return self.vert_pos
        pos = np.asarray(vert_pos, dtype=np.float64)
        if pos.shape != (self.nvert, 3):
            raise MeshError(
                f"mesh {self.name!r}: vert_pos must have shape ({self.nvert}, 3); received shape {pos.shape}"
            )
        return pos

    def volume(self, vert_pos=None) -> float:
        """Signed enclosed volume (m^3) at `vert_pos` (nvert, 3) m, default the rest shape.

        Positive for a closed, outward surface. For an open surface it is
        relative to the mean of the positions (see module function `volume`).
        """
        return volume(self._pos(vert_pos), self.face_vert)

    def volume_gradient(self, vert_pos=None) -> np.ndarray:
        """dV/dx at `vert_pos` (default rest), (nvert, 3) m^2 (see module function)."""
        return volume_gradient(self._pos(vert_pos), self.face_vert)

    def vert_area_vector(self, vert_pos=None) -> np.ndarray:
        """Area-weighted outward normal of each vertex, (nvert, 3) m^2.

        Sum over the incident faces of (face area * unit outward normal) / 3,
        i.e. (x_b - x_a) x (x_c - x_a) / 6 per face corner. Sums to zero over a
        closed surface, and sum_i a_i . x_i = 3 V.
        """
        pos = self._pos(vert_pos)
        face = self.face_vert
        a, b, c = pos[face[:, 0]], pos[face[:, 1]], pos[face[:, 2]]
        third = cross_rows(b - a, c - a) / 6.0
        return scatter_corners(face, third, third, third, self.nvert)

    def edge_length_mean(self, vert_pos=None) -> float:
        """Mean length of the unique edges (m) at `vert_pos`, default rest."""
        pos = self._pos(vert_pos)
        edge = pos[self.edge_vert[:, 1]] - pos[self.edge_vert[:, 0]]
        return float(np.mean(np.sqrt(np.sum(edge * edge, axis=1))))

    def require_closed(self, why: str) -> None:
        """Raise `MeshError` if the surface is open, naming its first border edges and `why`.

        why: what needs the closed surface, e.g. "a volume constraint needs a
        closed surface".
        """
        if self.closed:
            return
        edges = border_edges(self.face_vert, self.nvert)
        listed = few(edges, lambda edge: f"({edge[0]}, {edge[1]})")
        raise MeshError(
            f"{why}; mesh {self.name!r} is open: {len(edges)} border edges "
            f"(used by one face only), e.g. {listed}; expected every edge shared by two faces"
        )

    def components(self) -> list[np.ndarray]:
        """The surface's connected pieces (points joined by edges), each as its sorted
        point indices, the piece of point 0 first (then by their first point)."""
        label = components_label(self.edge_vert, self.nvert)
        if not label.any():
            return [np.arange(self.nvert)]
        order = np.argsort(label, kind="stable")
        _, size = np.unique(label, return_counts=True)
        return sorted(np.split(order, np.cumsum(size)[:-1]), key=lambda part: part[0])

    def require_one_piece(self, why: str) -> None:
        """Raise `MeshError` if the surface is several disjoint pieces, naming each (its
        points, where it is and, closed, its volume) and `why`."""
        parts = self.components()
        if len(parts) == 1:
            return

        def describe(part):
            face = self.face_vert[np.all(np.isin(self.face_vert, part), axis=1)]
            c = self.vert_pos[part].mean(axis=0)
            c[np.abs(c) < 1e-9 * np.ptp(self.vert_pos[part], axis=0).max()] = 0.0  # round-off of a zero
            centre = ", ".join(f"{x:.3g}" for x in c)
            return f"{len(part)} points about ({centre}) m enclosing {volume(self.vert_pos, face) * 1e3:.3g} L"

        raise MeshError(
            f"{why}; mesh {self.name!r} is {len(parts)} disjoint surfaces: {few(parts, describe)}; expected one "
            f"connected surface (give each body its own mesh and scene)"
        )

    def require_no_self_crossing(self, why: str) -> None:
        """Raise `MeshError` if faces of the surface pass through (or touch) each
        other, naming the first pairs of faces, their count and `why`."""
        from .intersect import crossing_faces

        pairs, count = crossing_faces(self.vert_pos, self.face_vert)
        if count:
            shown = pairs[:FEW]
            listed = ", ".join(f"faces {f} and {g}" for f, g in shown.tolist())
            if count > len(shown):
                listed += f" and {count - len(shown)} more pairs"
            raise MeshError(
                f"{why}; mesh {self.name!r} intersects itself: {count} pairs of faces cross, "
                f"e.g. {listed}; expected a surface that does not pass through itself"
            )

    def to_trimesh(self) -> trimesh.Trimesh:
        """A trimesh.Trimesh copy of the rest shape (vertices and faces kept as they are)."""
        import trimesh

        return trimesh.Trimesh(
            vertices=np.array(self.vert_pos),
            faces=np.array(self.face_vert, dtype=np.int64),
            process=False,
            validate=False,
        )


def components_label(edge_vert: np.ndarray, nvert: int) -> np.ndarray:
    """Each point's piece, named by its smallest point (nvert,) int64: labels passed along
    the edges, the smaller kept, and each label replaced by its own label's, until none
    changes (numpy alone: scipy's graph routines cost a run 0.2 s of CPU to import)."""
    label = np.arange(nvert)
    a, b = edge_vert[:, 0], edge_vert[:, 1]
    while True:
        low = np.minimum(label[a], label[b])
        new = label.copy()
        np.minimum.at(new, a, low)
        np.minimum.at(new, b, low)
        new = new[new]  # a label's own label: a long path's labels halve their distance each pass
        if np.array_equal(new, label):
            return label
        label = new


def _rebuild_mesh(vert_pos, face_vert, name, refinement=None):
    return Mesh(vert_pos, face_vert, name=name, refinement=refinement)
