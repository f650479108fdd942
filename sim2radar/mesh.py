"""Material-labelled triangle meshes: the scene representation every stage shares.

A scene is a list of :class:`MaterialMesh`. Procedural worlds and RGB reconstruction produce
them; the radar simulator consumes them. On disk a scene is a small YAML listing that maps
mesh files (PLY or OBJ) to materials::

    # corridor.yaml -- paths resolve against this file's folder
    meshes:
      - file: floor.ply
        material: concrete
        semantic: floor        # optional class label (door, wall, floor, ...)
      - file: door.obj
        material: metal
        semantic: door
        name: door_0           # optional; defaults to the file stem

Units: metres. Frame: whatever the caller uses (world frame for worlds, radar frame when a
scene is given straight to the simulator with ``pose=None``).
"""

from __future__ import annotations

import dataclasses
import re
import struct
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import yaml

from sim2radar.configio import load_yaml, short_text

__all__ = ["MaterialMesh", "MeshFileError", "load_mesh", "load_scene", "save_ply", "box_mesh",
           "cylinder_arrays", "cylinder_mesh"]


class MeshFileError(ValueError):
    """A mesh or scene file cannot be read; the message names the file, field and fix."""


@dataclasses.dataclass(frozen=True, eq=False)
class MaterialMesh:
    """A triangle mesh with one material.

    Attributes
    ----------
    vertices : (V, 3) float32
        Vertex positions [m].
    faces : (F, 3) int32
        Triangle vertex indices into ``vertices``.
    material : str
        Material name understood by :mod:`sim2radar.em` (e.g. ``"metal"``, ``"concrete"``).
    name : str
        Identifier, unique within a scene by convention.
    semantic : str
        Class label (``"door"``, ``"wall"``, ``"floor"``, ...); empty if unknown.
    """

    vertices: np.ndarray
    faces: np.ndarray
    material: str
    name: str = ""
    semantic: str = ""

    def __post_init__(self) -> None:
        v = np.ascontiguousarray(self.vertices, dtype=np.float32)
        f = np.ascontiguousarray(self.faces, dtype=np.int32)
        where = f"mesh {self.name!r}" if self.name else "mesh"
        if v.ndim != 2 or v.shape[1] != 3:
            raise ValueError(f"{where}: vertices must have shape (V, 3), got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3:
            raise ValueError(f"{where}: faces must have shape (F, 3), got {f.shape}")
        if not np.isfinite(v).all():
            raise ValueError(f"{where}: vertices contain NaN or inf")
        if f.size and (f.min() < 0 or f.max() >= len(v)):
            raise ValueError(
                f"{where}: face indices must lie in [0, {len(v) - 1}], "
                f"got [{f.min()}, {f.max()}]"
            )
        if not isinstance(self.material, str) or not self.material:
            raise ValueError(f"{where}: material must be a non-empty string")
        v.setflags(write=False)
        f.setflags(write=False)
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f)

    # -- geometry -------------------------------------------------------------------------
    @property
    def triangles(self) -> np.ndarray:
        """(F, 3, 3) float32 — the corner positions of each face [m]."""
        return self.vertices[self.faces]

    @property
    def face_normals(self) -> np.ndarray:
        """(F, 3) float32 — unit face normals (right-hand rule on the vertex order)."""
        t = self.triangles
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return (n / np.maximum(norm, 1e-12)).astype(np.float32)

    @property
    def area_m2(self) -> float:
        """Total surface area [m^2]."""
        t = self.triangles.astype(np.float64)
        return float(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1).sum())

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) float32 — axis-aligned min and max corner [m]."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    def transformed(self, matrix: np.ndarray) -> MaterialMesh:
        """Return a copy with vertices mapped by a (4, 4) homogeneous transform."""
        m = np.asarray(matrix, dtype=np.float64)
        if m.shape != (4, 4):
            raise ValueError(f"transform must be (4, 4), got {m.shape}")
        v = self.vertices.astype(np.float64) @ m[:3, :3].T + m[:3, 3]
        faces = self.faces if np.linalg.det(m[:3, :3]) > 0 else self.faces[:, ::-1]
        return dataclasses.replace(self, vertices=v, faces=faces)


# ---------------------------------------------------------------------------------------
# Construction helpers
# ---------------------------------------------------------------------------------------
def box_mesh(
    center: Sequence[float],
    size: Sequence[float],
    heading_rad: float = 0.0,
    *,
    material: str,
    name: str = "",
    semantic: str = "",
) -> MaterialMesh:
    """A closed box (12 outward-facing triangles).

    Parameters
    ----------
    center : (3,) [m]
    size : (3,) [m] — extent along the box's own x, y, z before rotation.
    heading_rad : float [rad] — rotation about +z.
    """
    c = np.asarray(center, dtype=np.float64)
    half = np.asarray(size, dtype=np.float64) / 2.0
    corners = np.array(
        [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64
    ) * half
    cos_h, sin_h = np.cos(heading_rad), np.sin(heading_rad)
    rot = np.array([[cos_h, -sin_h, 0.0], [sin_h, cos_h, 0.0], [0.0, 0.0, 1.0]])
    vertices = corners @ rot.T + c
    # corner index = 4*ix + 2*iy + iz ; faces listed counter-clockwise seen from outside
    faces = np.array(
        [
            [0, 1, 3], [0, 3, 2],  # -x
            [4, 6, 7], [4, 7, 5],  # +x
            [0, 4, 5], [0, 5, 1],  # -y
            [2, 3, 7], [2, 7, 6],  # +y
            [0, 2, 6], [0, 6, 4],  # -z
            [1, 5, 7], [1, 7, 3],  # +z
        ]
    )
    return MaterialMesh(vertices, faces, material=material, name=name, semantic=semantic)


def cylinder_arrays(
    base: Sequence[float],
    axis: Sequence[float],
    radius_m: float,
    length_m: float,
    segments: int = 16,
) -> tuple[np.ndarray, np.ndarray]:
    """A closed cylinder from ``base`` [m] along ``axis`` (normalised here) with ``radius_m``
    and ``length_m`` [m], its side a prism of ``segments`` flat facets: vertices (2S+2, 3)
    float64 and outward-facing faces (4S, 3) int64."""
    if segments < 3 or not radius_m > 0 or not length_m > 0:
        raise ValueError(f"cylinder needs >= 3 segments and a positive radius and length, got "
                         f"{segments}, {radius_m}, {length_m}")
    a = np.asarray(axis, dtype=np.float64)
    a = a / np.linalg.norm(a)
    helper = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(a, helper)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(a, e1)
    ang = 2 * np.pi * np.arange(segments) / segments
    ring = radius_m * (np.cos(ang)[:, None] * e1 + np.sin(ang)[:, None] * e2)
    b = np.asarray(base, dtype=np.float64)
    verts = np.concatenate([b + ring, b + a * length_m + ring, [b], [b + a * length_m]])
    s = segments
    i = np.arange(s)
    j = (i + 1) % s
    faces = np.concatenate([
        np.stack([i, j, s + j], axis=1), np.stack([i, s + j, s + i], axis=1),   # side
        np.stack([np.full(s, 2 * s), j, i], axis=1),                            # base cap
        np.stack([np.full(s, 2 * s + 1), s + i, s + j], axis=1),                # top cap
    ]).astype(np.int64)
    return verts, faces


def cylinder_mesh(
    base: Sequence[float],
    axis: Sequence[float],
    radius_m: float,
    length_m: float,
    segments: int = 16,
    *,
    material: str,
    name: str = "",
    semantic: str = "",
) -> MaterialMesh:
    """A closed cylinder mesh (:func:`cylinder_arrays`)."""
    v, f = cylinder_arrays(base, axis, radius_m, length_m, segments)
    return MaterialMesh(v, f, material=material, name=name, semantic=semantic)


# ---------------------------------------------------------------------------------------
# File I/O: PLY (ascii / binary) and OBJ readers, PLY writer, YAML scene listing
# ---------------------------------------------------------------------------------------
_PLY_TYPES = {
    "char": "b", "int8": "b", "uchar": "B", "uint8": "B",
    "short": "h", "int16": "h", "ushort": "H", "uint16": "H",
    "int": "i", "int32": "i", "uint": "I", "uint32": "I",
    "float": "f", "float32": "f", "double": "d", "float64": "d",
}


def _triangulate(polygons: list[list[int]]) -> np.ndarray:
    """Fan-triangulate polygons with >= 3 corners into (F, 3) indices."""
    tris = [[p[0], p[i], p[i + 1]] for p in polygons for i in range(1, len(p) - 1)]
    return np.asarray(tris, dtype=np.int64).reshape(-1, 3)


def _read_ply(path: Path) -> tuple[np.ndarray, np.ndarray]:
    data = path.read_bytes()
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise MeshFileError(f"{path}: not a PLY file (missing 'ply' magic or 'end_header')")
    header = data[:end].decode("ascii", errors="replace").splitlines()
    body_start = data.index(b"\n", end) + 1
    fmt = None
    elements: list[tuple[str, int, list[tuple]]] = []
    for line in header:
        tok = line.split()
        if not tok:
            continue
        if tok[0] == "format":
            fmt = tok[1]
        elif tok[0] == "element":
            elements.append((tok[1], int(tok[2]), []))
        elif tok[0] == "property" and elements:
            if tok[1] == "list":
                elements[-1][2].append(("list", tok[2], tok[3], tok[4]))
            else:
                elements[-1][2].append(("scalar", tok[1], tok[2]))
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise MeshFileError(f"{path}: unsupported PLY format {fmt!r}")
    names = [e[0] for e in elements]
    if "vertex" not in names:
        raise MeshFileError(f"{path}: PLY has no 'vertex' element")

    vertices = None
    polygons: list[list[int]] = []
    if fmt == "ascii":
        tokens = data[body_start:].decode("ascii", errors="replace").split()
        pos = 0
        for name, count, props in elements:
            rows = []
            for _ in range(count):
                row = []
                for prop in props:
                    if prop[0] == "list":
                        n = int(tokens[pos])
                        row.append([float(t) for t in tokens[pos + 1 : pos + 1 + n]])
                        pos += 1 + n
                    else:
                        row.append(float(tokens[pos]))
                        pos += 1
                rows.append(row)
            if name == "vertex":
                vertices = _ply_vertices(path, props, rows)
            elif name == "face":
                polygons = _ply_faces(path, props, rows)
    else:
        endian = "<" if fmt == "binary_little_endian" else ">"
        pos = body_start
        for name, count, props in elements:
            if all(p[0] == "scalar" for p in props):
                dtype = np.dtype([(p[2], endian + _PLY_TYPES[p[1]]) for p in props])
                arr = np.frombuffer(data, dtype=dtype, count=count, offset=pos)
                pos += dtype.itemsize * count
                if name == "vertex":
                    try:
                        vertices = np.stack([arr["x"], arr["y"], arr["z"]], axis=1)
                    except ValueError as exc:
                        raise MeshFileError(f"{path}: vertex element lacks x/y/z") from exc
                continue
            rows = []
            for _ in range(count):
                row = []
                for prop in props:
                    if prop[0] == "list":
                        cnt_fmt = endian + _PLY_TYPES[prop[1]]
                        (n,) = struct.unpack_from(cnt_fmt, data, pos)
                        pos += struct.calcsize(cnt_fmt)
                        item_fmt = endian + _PLY_TYPES[prop[2]] * n
                        row.append(list(struct.unpack_from(item_fmt, data, pos)))
                        pos += struct.calcsize(item_fmt)
                    else:
                        f = endian + _PLY_TYPES[prop[1]]
                        (val,) = struct.unpack_from(f, data, pos)
                        pos += struct.calcsize(f)
                        row.append(val)
                rows.append(row)
            if name == "vertex":
                vertices = _ply_vertices(path, props, rows)
            elif name == "face":
                polygons = _ply_faces(path, props, rows)
    return np.asarray(vertices, dtype=np.float64), _triangulate(polygons)


def _ply_vertices(path: Path, props: list[tuple], rows: list[list]) -> np.ndarray:
    names = [p[-1] for p in props]
    try:
        idx = [names.index(k) for k in ("x", "y", "z")]
    except ValueError as exc:
        raise MeshFileError(f"{path}: vertex element lacks x/y/z properties") from exc
    return np.asarray([[r[i] for i in idx] for r in rows], dtype=np.float64).reshape(-1, 3)


def _ply_faces(path: Path, props: list[tuple], rows: list[list]) -> list[list[int]]:
    names = [p[-1] for p in props]
    for key in ("vertex_indices", "vertex_index"):
        if key in names:
            i = names.index(key)
            return [[int(v) for v in r[i]] for r in rows]
    raise MeshFileError(f"{path}: face element lacks a 'vertex_indices' list property")


def _read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    vertices: list[list[float]] = []
    polygons: list[list[int]] = []
    for lineno, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        tok = line.split()
        if not tok:
            continue
        try:
            if tok[0] == "v":
                vertices.append([float(t) for t in tok[1:4]])
            elif tok[0] == "f":
                idx = [int(re.split(r"/", t)[0]) for t in tok[1:]]
                # OBJ is 1-based; negative indices count back from the latest vertex
                polygons.append([i - 1 if i > 0 else len(vertices) + i for i in idx])
        except (ValueError, IndexError) as exc:
            raise MeshFileError(f"{path}:{lineno}: cannot parse {line.strip()!r}") from exc
    return np.asarray(vertices, dtype=np.float64).reshape(-1, 3), _triangulate(polygons)


def load_mesh(
    path: str | Path, material: str, *, name: str | None = None, semantic: str = ""
) -> MaterialMesh:
    """Read a PLY (ascii or binary) or OBJ file as a :class:`MaterialMesh`.

    Raises
    ------
    MeshFileError
        If the file is missing, of an unknown type, unparseable, or has no faces.
    """
    path = Path(path)
    if not path.is_file():
        raise MeshFileError(f"{path}: mesh file not found")
    suffix = path.suffix.lower()
    if suffix == ".ply":
        vertices, faces = _read_ply(path)
    elif suffix == ".obj":
        vertices, faces = _read_obj(path)
    else:
        raise MeshFileError(f"{path}: unsupported mesh type {suffix!r}; use .ply or .obj")
    if len(faces) == 0:
        raise MeshFileError(f"{path}: mesh has no faces")
    try:
        return MaterialMesh(
            vertices, faces, material=material, name=name or path.stem, semantic=semantic
        )
    except ValueError as exc:
        raise MeshFileError(f"{path}: {exc}") from exc


def save_ply(mesh: MaterialMesh, path: str | Path) -> Path:
    """Write ``mesh`` as a binary little-endian PLY (float32 vertices, int32 faces)."""
    path = Path(path)
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"comment material {mesh.material}\n"
        f"element vertex {len(mesh.vertices)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        f"element face {len(mesh.faces)}\n"
        "property list uchar int vertex_indices\nend_header\n"
    ).encode("ascii")
    face_rec = np.empty(len(mesh.faces), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    face_rec["n"] = 3
    face_rec["i"] = mesh.faces
    path.write_bytes(header + mesh.vertices.astype("<f4").tobytes() + face_rec.tobytes())
    return path


def load_scene(path: str | Path) -> list[MaterialMesh]:
    """Read a YAML scene listing (see module docstring) into a list of meshes.

    Mesh paths resolve against the YAML file's folder. Errors name the file, the entry and
    the field at fault.
    """
    path = Path(path)
    if not path.is_file():
        raise MeshFileError(f"{path}: scene file not found")
    try:
        doc = load_yaml(path.read_text())
    except yaml.YAMLError as exc:
        raise MeshFileError(f"{path}: invalid YAML: {short_text(exc)}") from None
    if not isinstance(doc, dict) or not isinstance(doc.get("meshes"), list) or not doc["meshes"]:
        raise MeshFileError(
            f"{path}: expected a mapping with a non-empty 'meshes' list, "
            "e.g. 'meshes: [{file: floor.ply, material: concrete}]'"
        )
    meshes = []
    for i, entry in enumerate(doc["meshes"]):
        where = f"{path}: meshes[{i}]"
        if not isinstance(entry, dict):
            raise MeshFileError(f"{where}: expected a mapping with 'file' and 'material'")
        for field in ("file", "material"):
            if not entry.get(field):
                raise MeshFileError(f"{where}: missing field '{field}'")
        unknown = set(entry) - {"file", "material", "name", "semantic"}
        if unknown:
            raise MeshFileError(
                f"{where}: unknown field(s) {sorted(unknown)}; allowed: file, material, name, semantic"
            )
        meshes.append(
            load_mesh(
                path.parent / entry["file"],
                str(entry["material"]),
                name=entry.get("name"),
                semantic=str(entry.get("semantic", "")),
            )
        )
    return meshes
