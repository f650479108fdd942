"""Scene files with radar poses and ground-truth boxes, on top of :func:`sim2radar.mesh.load_scene`.

A scene YAML lists meshes (see :mod:`sim2radar.mesh`) and may add where the radar stands and
the labelled boxes::

    name: corridor                 # optional; defaults to the file stem
    meshes:
      - {file: floor.ply, material: concrete, semantic: floor}
      - {file: door_metal.ply, material: metal, semantic: door}
    radar_poses:                   # optional; default: one pose at the origin (identity)
      - position: [0.0, 0.0, 1.2]  # radar origin in the world frame [m]
        yaw_deg: 0.0               # about world +z, counter-clockwise (toward +y) [deg]
        pitch_deg: 0.0             # about the radar's +y; positive tilts the boresight down [deg]
        roll_deg: 0.0              # about the radar's +x [deg]
      - matrix: [[1,0,0,0],[0,1,0,0],[0,0,1,1.2],[0,0,0,1]]   # or a full radar-to-world (4, 4)
    boxes:                         # optional ground-truth boxes in the world frame
      - label: door
        box: [8.0, 0.0, 1.0, 0.05, 0.9, 2.0, 0.0]   # x y z dx dy dz [m], heading [rad]

Frames: world z up; the radar frame is x forward, y left, z up (DESIGN.md). Boxes follow
``sim2radar.vocab.BOX_FIELDS`` with z at the box centre.
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import numpy as np
import yaml

from sim2radar.mesh import MaterialMesh, MeshFileError, load_scene

__all__ = [
    "Scene",
    "load_scene_file",
    "scene_digest",
    "pose_matrix",
    "boxes_to_frame",
    "check_materials",
]


@dataclasses.dataclass(frozen=True, eq=False)
class Scene:
    """A material-labelled scene with radar poses and labelled boxes.

    Attributes
    ----------
    name : str
        Scene identifier (YAML ``name`` or the file stem).
    meshes : tuple of MaterialMesh
        World-frame geometry [m].
    radar_poses : (K, 4, 4) float64
        Radar-to-world transform of each frame [m].
    boxes_world : (M, 7) float32
        Ground-truth boxes ``x y z dx dy dz heading`` in the world frame [m, rad].
    box_labels : tuple of str
        (M,) class names.
    path : Path or None
        The YAML file the scene came from.
    """

    name: str
    meshes: tuple[MaterialMesh, ...]
    radar_poses: np.ndarray
    boxes_world: np.ndarray
    box_labels: tuple[str, ...] = ()
    path: Path | None = None

    def boxes_in_radar(self, frame_index: int) -> np.ndarray:
        """(M, 7) float32 boxes in the radar frame of ``frame_index`` [m, rad]."""
        return boxes_to_frame(self.boxes_world, self.radar_poses[frame_index])


def pose_matrix(
    position, yaw_deg: float = 0.0, pitch_deg: float = 0.0, roll_deg: float = 0.0
) -> np.ndarray:
    """Radar-to-world (4, 4) from a position [m] and yaw/pitch/roll [deg].

    ``R = Rz(yaw) · Ry(pitch) · Rx(roll)`` (intrinsic z-y'-x'' Tait–Bryan angles); a positive
    pitch tilts the boresight (+x) down, i.e. toward world -z.
    """
    p = np.asarray(position, dtype=np.float64).reshape(3)
    yaw, pitch, roll = np.radians([yaw_deg, pitch_deg, roll_deg])
    cz, sz = np.cos(yaw), np.sin(yaw)
    cy, sy = np.cos(pitch), np.sin(pitch)
    cx, sx = np.cos(roll), np.sin(roll)
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    m = np.eye(4)
    m[:3, :3] = rz @ ry @ rx
    m[:3, 3] = p
    return m


def boxes_to_frame(boxes_world: np.ndarray, radar_to_world: np.ndarray) -> np.ndarray:
    """Express world-frame boxes in the radar frame.

    Parameters
    ----------
    boxes_world : (M, 7) — x y z dx dy dz heading, world frame [m, rad]
    radar_to_world : (4, 4) — radar pose [m]

    Returns
    -------
    (M, 7) float32 — the same boxes in the radar frame. Centres are exact for any pose; the
    heading subtracts the radar's yaw, which is exact when the radar has no roll/pitch (boxes
    stay upright in ``BOX_FIELDS``) and a small-angle approximation otherwise.
    """
    b = np.asarray(boxes_world, dtype=np.float64).reshape(-1, 7)
    m = np.asarray(radar_to_world, dtype=np.float64)
    rot, t = m[:3, :3], m[:3, 3]
    centres = (b[:, :3] - t) @ rot  # R^T (c - t), row-vector form
    yaw = np.arctan2(rot[1, 0], rot[0, 0])
    heading = np.mod(b[:, 6] - yaw + np.pi, 2 * np.pi) - np.pi
    return np.concatenate([centres, b[:, 3:6], heading[:, None]], axis=1).astype(np.float32)


def check_materials(meshes, where: str) -> None:
    """Raise :class:`MeshFileError` naming the mesh if a material is unknown to :mod:`sim2radar.em`."""
    from sim2radar.em import UnknownMaterialError, get_material

    for m in meshes:
        try:
            get_material(m.material)
        except UnknownMaterialError as exc:
            raise MeshFileError(f"{where}: mesh {m.name!r}: {exc}") from None


def _parse_pose(entry, where: str) -> np.ndarray:
    if not isinstance(entry, dict):
        raise MeshFileError(f"{where}: expected a mapping with 'position' (+ angles) or 'matrix'")
    if "matrix" in entry:
        extra = set(entry) - {"matrix"}
        if extra:
            raise MeshFileError(f"{where}: 'matrix' cannot be combined with {sorted(extra)}")
        try:
            m = np.asarray(entry["matrix"], dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise MeshFileError(f"{where}.matrix: not a numeric 4x4 matrix: {exc}") from None
        if m.shape != (4, 4) or not np.isfinite(m).all():
            raise MeshFileError(f"{where}.matrix: expected a finite 4x4 matrix, got shape {m.shape}")
        rot = m[:3, :3]
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-5) or np.linalg.det(rot) < 0:
            raise MeshFileError(f"{where}.matrix: the 3x3 block must be a rotation (orthonormal, det +1)")
        if not np.allclose(m[3], [0, 0, 0, 1]):
            raise MeshFileError(f"{where}.matrix: the last row must be [0, 0, 0, 1]")
        return m
    allowed = {"position", "yaw_deg", "pitch_deg", "roll_deg"}
    unknown = set(entry) - allowed
    if unknown:
        raise MeshFileError(f"{where}: unknown field(s) {sorted(unknown)}; allowed: {sorted(allowed)} or matrix")
    if "position" not in entry:
        raise MeshFileError(f"{where}: missing field 'position' ([x, y, z] in metres)")
    try:
        pos = np.asarray(entry["position"], dtype=np.float64)
        angles = [float(entry.get(k, 0.0)) for k in ("yaw_deg", "pitch_deg", "roll_deg")]
    except (TypeError, ValueError) as exc:
        raise MeshFileError(f"{where}: position/angles must be numbers: {exc}") from None
    if pos.shape != (3,) or not np.isfinite(pos).all():
        raise MeshFileError(f"{where}.position: expected [x, y, z] in metres, got {entry['position']!r}")
    return pose_matrix(pos, *angles)


def _parse_boxes(entries, where: str) -> tuple[np.ndarray, tuple[str, ...]]:
    if not isinstance(entries, list):
        raise MeshFileError(f"{where}: expected a list of {{label, box}} mappings")
    boxes, labels = [], []
    for i, e in enumerate(entries):
        w = f"{where}[{i}]"
        if not isinstance(e, dict) or "box" not in e:
            raise MeshFileError(f"{w}: expected a mapping with 'box: [x, y, z, dx, dy, dz, heading]'")
        try:
            b = np.asarray(e["box"], dtype=np.float64)
        except (TypeError, ValueError):
            b = np.zeros(0)
        if b.shape != (7,) or not np.isfinite(b).all():
            raise MeshFileError(f"{w}.box: expected 7 numbers x y z dx dy dz heading, got {e['box']!r}")
        if (b[3:6] <= 0).any():
            raise MeshFileError(f"{w}.box: sizes dx, dy, dz must be positive, got {b[3:6].tolist()}")
        boxes.append(b)
        labels.append(str(e.get("label", "door")))
    arr = np.asarray(boxes, dtype=np.float32).reshape(-1, 7)
    return arr, tuple(labels)


def load_scene_file(path: str | Path, *, validate_materials: bool = True) -> Scene:
    """Read a scene YAML (meshes + optional ``name``, ``radar_poses``, ``boxes``).

    Raises
    ------
    MeshFileError
        Naming the file and the entry/field at fault: missing/broken mesh files, unknown
        materials (``validate_materials``), malformed poses or boxes.
    """
    path = Path(path)
    meshes = load_scene(path)  # validates the file, the mesh entries and the mesh files
    doc = yaml.safe_load(path.read_text())
    allowed = {"name", "meshes", "radar_poses", "boxes", "description"}
    unknown = set(doc) - allowed
    if unknown:
        raise MeshFileError(f"{path}: unknown top-level field(s) {sorted(unknown)}; allowed: {sorted(allowed)}")
    if validate_materials:
        check_materials(meshes, str(path))
    poses_doc = doc.get("radar_poses")
    if poses_doc is None:
        poses = np.eye(4)[None]
    else:
        if not isinstance(poses_doc, list) or not poses_doc:
            raise MeshFileError(f"{path}: radar_poses must be a non-empty list")
        poses = np.stack([_parse_pose(e, f"{path}: radar_poses[{i}]") for i, e in enumerate(poses_doc)])
    boxes, labels = _parse_boxes(doc.get("boxes", []) or [], f"{path}: boxes")
    name = str(doc.get("name") or path.stem)
    return Scene(
        name=name,
        meshes=tuple(meshes),
        radar_poses=poses,
        boxes_world=boxes,
        box_labels=labels,
        path=path,
    )


def scene_digest(path: str | Path) -> str:
    """SHA-256 over a scene YAML and every mesh file it lists (content, not timestamps).

    Editing the YAML (materials, poses, boxes) or any mesh file changes the digest; touching or
    copying the files elsewhere does not.
    """
    path = Path(path)
    if not path.is_file():
        raise MeshFileError(f"{path}: scene file not found")
    raw = path.read_bytes()
    h = hashlib.sha256()
    h.update(b"scene-yaml\0" + raw)
    try:
        doc = yaml.safe_load(raw)
    except yaml.YAMLError as exc:
        raise MeshFileError(f"{path}: invalid YAML: {exc}") from exc
    entries = doc.get("meshes", []) if isinstance(doc, dict) else []
    for entry in entries if isinstance(entries, list) else []:
        if isinstance(entry, dict) and entry.get("file"):
            mesh_path = path.parent / str(entry["file"])
            h.update(f"\0mesh:{entry['file']}\0".encode())
            if mesh_path.is_file():
                h.update(hashlib.sha256(mesh_path.read_bytes()).digest())
            else:
                h.update(b"<missing>")
    return h.hexdigest()
