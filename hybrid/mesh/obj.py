"""Wavefront OBJ files read with their vertices in file order.

trimesh's OBJ loader keeps only the vertices the faces use and, with texture
coordinates or materials, renumbers or splits them, so vertex k of the file is
not vertex k of the mesh: `indices` regions and `per_vertex_kg` would point at
other points. This reader keeps every `v` line as vertex k, in order (an
unused one is then refused by the validation, never dropped), takes the
position index of each `f` corner (`i`, `i/t`, `i//n`, `i/t/n`; negative
indices count back from the last vertex read) and splits polygons of more
than three corners into a fan from their first corner. Other statements
(normals, texture coordinates, groups, materials) do not change the surface
and are skipped.

`write_obj` writes positions with 17 significant digits, which read back to
the same doubles: a mesh saved and loaded gives the same runs to the bit.
"""

from __future__ import annotations

import numpy as np

from hybrid.errors import MeshError

__all__ = ["read_obj", "write_obj"]


def read_obj(path: str):
    """(vert_pos (nvert, 3) float64, face_vert (nface, 3) int64) of an OBJ file, in file order.

    Raises MeshError naming the path and the line for a malformed `v` or `f` statement.
    """
    verts: list[list[float]] = []
    faces: list[tuple[int, int, int]] = []
    try:
        text = open(path, encoding="utf-8", errors="replace").read()
    except OSError as exc:
        raise MeshError(f"mesh file {path!r} cannot be read: {exc.strerror}") from None
    for number, line in enumerate(text.replace("\\\n", " ").splitlines(), start=1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        if words[0] == "v":
            try:
                xyz = [float(w) for w in words[1:4]]
            except ValueError:
                xyz = []
            if len(xyz) != 3:
                raise MeshError(
                    f"mesh file {path!r} line {number}: expected 'v x y z' with three numbers; "
                    f"received {line.strip()[:80]!r}"
                )
            verts.append(xyz)
        elif words[0] == "f":
            corners = []
            for word in words[1:]:
                head = word.split("/", 1)[0]
                try:
                    k = int(head)
                except ValueError:
                    k = 0
                if k == 0 or (k < 0 and -k > len(verts)):
                    raise MeshError(
                        f"mesh file {path!r} line {number}: face corner {word!r} is not a vertex "
                        f"index (1..{len(verts)}, or -1..-{len(verts)} counting back)"
                    )
                corners.append(k - 1 if k > 0 else len(verts) + k)
            if len(corners) < 3:
                raise MeshError(
                    f"mesh file {path!r} line {number}: a face needs at least three corners; "
                    f"received {line.strip()[:80]!r}"
                )
            faces.extend((corners[0], corners[j], corners[j + 1]) for j in range(1, len(corners) - 1))
    if not faces:
        raise MeshError(f"mesh file {path!r}: no faces ('f' statements); expected a triangle surface")
    return np.array(verts, dtype=np.float64).reshape(-1, 3), np.array(faces, dtype=np.int64)


def write_obj(path, vert_pos, face_vert) -> None:
    """An OBJ file of the surface: a `v` line per vertex in order (17 significant
    digits: the same doubles read back), an `f` line per triangle (1-based)."""
    pos = np.asarray(vert_pos, np.float64)
    face = np.asarray(face_vert, np.int64) + 1
    lines = [f"v {x:.17g} {y:.17g} {z:.17g}" for x, y, z in pos.tolist()]
    lines += [f"f {a} {b} {c}" for a, b, c in face.tolist()]
    with open(path, "w") as f:
        f.write("\n".join(lines) + "\n")
