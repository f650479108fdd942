"""A lab's own RGB captures -> radar frames: the capture folder, radar poses in the reconstructed
free space, and one radar frame with its door labels (no Prefect, no store).

Capture folder layout (one scene = one RGB view, as in the paper: 5 views -> 270 frames)::

    captures/
      intrinsics.yaml          # optional: shared by every scene without its own
      radar.yaml               # optional: shared radar mount / poses (see below)
      corridor_a/
        rgb.png                # the RGB image (rgb.* or image.*: png, jpg, jpeg)
        intrinsics.yaml        # fx, fy, cx, cy, width, height (or K); optional rig calibration:
                               #   camera_height_m, camera_pitch_deg [+ camera_roll_deg] | up_cam
        lidar.npy              # optional (N, 3) LiDAR points, camera frame (x right, y down,
                               #   z forward) [m]; needed by the default (LiDAR) depth backend
        radar.yaml             # optional: radar_from_camera (4x4, camera (OpenCV) -> radar
                               #   (x fwd, y left, z up)); poses: [[x_m, y_m, yaw_deg], ...]
        views/                 # optional: other views of the same scene, fused into its
          a/rgb.png            #   reconstruction for the radar's field of view (one folder
          a/lidar.npy          #   each: rgb.*, optional intrinsics.yaml (else the scene's)
          b/...                #   and lidar.npy)
        poses.txt              # with views/: each view's camera -> world pose, one line each:
                               #   NAME r00 r01 r02 t0 r10 ... t2 0 0 0 1 (4x4 row-major, [m]);
                               #   NAME "." is the scene's own view, others views/NAME
      corridor_b/ ...

Views. A camera sees about ±33°, the radar ±60°: the scene's own image alone leaves the radar
nothing to see outside the camera's view. With ``views/`` and ``poses.txt`` the scene's
reconstruction is fused with the first ``reconstruction.fusion.frames`` views listed in
``poses.txt`` (each reconstructed from its own image and depth, moved by the poses and kept
where the scene's own camera does not look: :func:`sim2radar.reconstruct.fusion.fuse_views`),
as the procedural path fuses a rig's previous frames. Without them a scene is its one image
(the paper's pipeline).

Frames. A reconstruction is in its **level frame** (x forward, y left, z up, origin at the
camera; :meth:`~sim2radar.reconstruct.LabeledScene.meshes_in`). The radar's mount on the rig is
``mount = level_from_camera @ inv(radar_from_camera)`` (identity without ``radar.yaml``: the
radar at the camera, level). A radar **pose** is ``radar_to_level = rig(x, y, yaw) @ mount``,
the rig moved ``x`` forward and ``y`` left on the floor and turned by ``yaw`` about z. Poses
come from ``radar.yaml`` or are sampled (:class:`PoseSampling`); frame 0 is the capture pose.

A sampled (or given) pose is kept only where the radar is in **observed free space**: in the
camera's horizontal field of view, with a clear line of sight from the camera to it (the first
surface lies at least ``clearance_m`` beyond it) and ``clearance_m`` to the nearest surface in
8 horizontal directions (a radar inside a wall or a cupboard is rejected).

Labels are the reconstructed door boxes in each radar frame that the radar sees on the
reconstructed geometry (:func:`sim2radar.factory.labels.radar_visibility`, the rule of the
procedural path).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator, model_validator

from sim2radar.configio import DEFAULT_RADAR
from sim2radar.factory.labels import (
    DEFAULT_POINT_CLOUD_RANGE_M,
    ClassName,
    LabelConfig,
    radar_visibility,
    scene_ray_caster,
)
from sim2radar.factory.spec import (
    RadarSetting,
    ReconstructionSetting,
    resolve_radar,
    resolve_reconstruction,
)
from sim2radar.vocab import MAX_ID_LENGTH, id_problem

__all__ = [
    "CaptureScene",
    "CaptureSpec",
    "capture_settings",
    "PoseSampling",
    "find_captures",
    "load_capture_frame",
    "rig_pose",
    "radar_mount",
    "sample_radar_poses",
    "free_space_mask",
    "capture_frame",
    "read_poses_txt",
    "read_radar_yaml",
    "rigid_transform",
    "scene_views",
    "write_capture_folder",
]

log = logging.getLogger(__name__)

_IMAGE_NAMES = ("rgb", "image")
_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
#: how far ``radar_from_camera``'s rotation part may be from a rotation (max |R^T R - I| and
#: |det R - 1|) [-]: loose enough for a calibration printed to 5 decimals, tight enough to
#: refuse a scale (1.001 is a 1 mm error per metre) or a shear
RIGID_TOLERANCE = 1e-4


# ---------------------------------------------------------------------------------------------
# Configuration
# ---------------------------------------------------------------------------------------------
class PoseSampling(BaseModel):
    """Radar poses per reconstructed scene, sampled in its observed free space.

    Attributes
    ----------
    frames : int — radar frames per scene (the paper: 270 frames from 5 views = 54), frame 0
        at the capture pose.
    forward_m, lateral_m : (min, max) [m] — rig displacement forward (x) and left (y) of the
        capture pose, level frame.
    yaw_deg : (min, max) [deg] — rig turn about z (counter-clockwise seen from above).
    height_m : (min, max) [m] — radar height offset from the capture pose.
    clearance_m : float [m] — free space the radar needs around it and beyond it.
    max_candidates : int — candidates drawn per wanted frame before giving up.
    """

    model_config = ConfigDict(frozen=True, extra="forbid")

    frames: int = Field(54, ge=1, le=10_000)
    forward_m: tuple[float, float] = (0.0, 2.5)
    lateral_m: tuple[float, float] = (-0.6, 0.6)
    yaw_deg: tuple[float, float] = (-20.0, 20.0)
    height_m: tuple[float, float] = (0.0, 0.0)
    clearance_m: float = Field(0.3, ge=0.0, le=5.0)
    max_candidates: int = Field(50, ge=1, le=10_000)

    @field_validator("forward_m", "lateral_m", "yaw_deg", "height_m")
    @classmethod
    def _ordered(cls, v: tuple[float, float]) -> tuple[float, float]:
        if not (math.isfinite(v[0]) and math.isfinite(v[1]) and v[0] <= v[1]):
            raise ValueError(f"must be a finite (min, max) with min <= max, got {list(v)}")
        return v


class CaptureSpec(BaseModel):
    """Resolved configuration of a capture-folder run (everything but the scenes and the store).

    Attributes
    ----------
    radar : RadarConfig
    reconstruction : ReconstructionConfig — backends for depth, segments and materials.
    poses : PoseSampling
    labels : LabelConfig — a door is a label when the radar sees enough of its doorway.
    class_name : str — label class of the door boxes.
    seed : int — run seed: pose sampling and radar noise derive from it.
    export_label_range_m : (6,) or None — OpenPCDet exports keep labels whose centre lies in
        this point-cloud range [m] (the detector's; None keeps all).
    frames_per_task : int — radar poses simulated per Prefect task.
    """

    model_config = ConfigDict(frozen=True, extra="forbid", validate_default=True)

    radar: RadarSetting = DEFAULT_RADAR
    reconstruction: ReconstructionSetting = None
    poses: PoseSampling = PoseSampling()
    labels: LabelConfig = LabelConfig()
    class_name: ClassName = "door"
    seed: int = 0
    export_label_range_m: tuple[float, ...] | None = DEFAULT_POINT_CLOUD_RANGE_M
    frames_per_task: int = Field(18, ge=1, le=10_000)

    #: The export helpers shared with the procedural path read these.
    geometries: tuple[str, ...] = ("reconstructed",)
    material_override: None = None

    @model_validator(mode="before")
    @classmethod
    def _resolve(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            return data
        data = dict(data)
        data["radar"] = resolve_radar(data.get("radar", DEFAULT_RADAR))
        rec = resolve_reconstruction(data.get("reconstruction"))
        if any(s.name == "oracle" for s in (rec.depth, rec.segments, rec.materials)):
            raise ValueError("reconstruction: 'oracle' backends need procedural-world ground "
                             "truth; a capture folder has none (use builtin, moge, sam2-gdino, "
                             "vlm, prior)")
        data["reconstruction"] = rec
        if data.get("export_label_range_m") is not None:
            data["export_label_range_m"] = tuple(float(v) for v in data["export_label_range_m"])
        return data

    @property
    def view(self) -> tuple[float, float, float]:
        """(azimuth FOV [deg], elevation FOV [deg], max range [m]) of the radar."""
        r = self.radar
        return float(r.azimuth_fov_deg), float(r.elevation_fov_deg), float(r.max_range_m)


#: Generate settings that describe procedural worlds and mean nothing for a capture folder.
PROCEDURAL_ONLY = ("worlds", "first_seed", "geometry", "world", "rig", "material_override")


def capture_settings(cfg: dict[str, Any], config_path: str | os.PathLike | None, *,
                     frames: int | None, radar: str | None, reconstruction: str | None,
                     seed: int | None) -> dict[str, Any]:
    """:class:`~sim2radar.factory.captures.CaptureSpec` fields from a generate YAML (already
    read) and the command-line options (which win).

    Raises
    ------
    ValueError naming the file and the setting that does not apply to captures.
    """
    where = f"{config_path}: " if config_path is not None else ""
    bad = [k for k in PROCEDURAL_ONLY if cfg.get(k) is not None]
    if bad:
        raise ValueError(f"{where}{bad} describe procedural worlds; a capture folder run takes "
                         "radar, reconstruction, seed, class_name, labels, poses, frames, "
                         "export_label_range_m, dataset")
    poses = dict(cfg.get("poses") or {})
    n = frames if frames is not None else cfg.get("frames")
    if n is not None:
        poses["frames"] = n
    out: dict[str, Any] = {
        "radar": radar or cfg.get("radar", DEFAULT_RADAR),
        "reconstruction": reconstruction or cfg.get("reconstruction"),
        "poses": poses,
        "seed": seed if seed is not None else cfg.get("seed", 0),
        "class_name": cfg.get("class_name", "door"),
        "labels": cfg.get("labels") or {},
    }
    if "export_label_range_m" in cfg:
        from sim2radar.factory.spec import label_range

        out["export_label_range_m"] = label_range(cfg["export_label_range_m"])
    return out



# ---------------------------------------------------------------------------------------------
# The capture folder
# ---------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class CaptureScene:
    """One scene of a capture folder: its files (paths as strings; absent optional files None).

    ``radar`` is the ``radar.yaml`` that applies (the scene's, else the folder's) or None.
    """

    scene_id: str
    folder: str
    image: str | None
    intrinsics: str | None
    lidar: str | None = None
    radar: str | None = None
    #: ``poses.txt`` (None: absent) and the folders of ``views/`` (sorted)
    poses: str | None = None
    views: tuple[str, ...] = ()


def _image_in(folder: Path) -> Path | None:
    found = [p for p in sorted(folder.iterdir())
             if p.stem.lower() in _IMAGE_NAMES and p.suffix.lower() in _IMAGE_SUFFIXES]
    return found[0] if found else None


def _holds_scene_files(folder: Path) -> bool:
    """Whether ``folder`` holds an image or an ``intrinsics.yaml`` (what makes a scene)."""
    try:
        return _image_in(folder) is not None or (folder / "intrinsics.yaml").is_file()
    except OSError:  # unreadable: not a scene
        return False


def _note_outside_links(paths, root: Path, said: set[str]) -> None:
    """Log one line per path in ``paths`` that is a symlink to somewhere outside ``root``
    (followed all the same; said once per link)."""
    inside = root.resolve()
    for p in paths:
        if p is None or not p.is_symlink() or str(p) in said:
            continue
        try:
            target = p.resolve()
        except (RuntimeError, OSError):  # a symlink loop: its scene fails alone, when read
            said.add(str(p))
            log.warning("capture folder %s: %s is a symlink loop; its scene will fail", root, p)
            continue
        if target != inside and inside not in target.parents:
            said.add(str(p))
            log.warning("capture folder %s: %s is a symlink to %s, outside the capture folder; "
                        "following it", root, p, target)


def find_captures(root: str | os.PathLike, *, warn: bool = True) -> list[CaptureScene]:
    """The scenes of a capture folder: every sub-folder holding an image or an intrinsics
    file, sorted by name. Missing files are left None here and reported per scene by
    :func:`load_capture_frame`, so one broken scene does not stop the others.

    With ``warn``, one warning line (logger ``sim2radar.factory.captures``) for each folder
    that looks like a scene but is skipped (a name starting with ``.``, such as ``...``; a
    symlink to nothing) and for each symlink to outside the folder (a scene folder or one of
    its files; followed). Pass ``warn=False`` where the folder was already listed.

    Raises
    ------
    ValueError — ``root`` is not a folder or holds no scene folder.
    """
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"{root}: capture folder not found; give a folder with one sub-folder "
                         "per scene (rgb.png, intrinsics.yaml, optional lidar.npy)")
    shared_k = root / "intrinsics.yaml"
    shared_radar = root / "radar.yaml"
    scenes, hidden, bad_names, said = [], [], [], set()
    for entry in sorted(root.iterdir()):
        if entry.is_symlink() and not entry.exists():
            if warn:
                log.warning("capture folder %s: skipped %r: a symlink to %s, which does not "
                            "exist; fix or remove the link", root, entry.name,
                            os.readlink(entry))
            continue
        if not entry.is_dir():
            continue
        if entry.name.startswith("."):
            if _holds_scene_files(entry):
                hidden.append(entry.name)
                if warn:
                    log.warning("capture folder %s: skipped folder %r: a name starting with '.' "
                                "is hidden (like .git); rename it without the leading dot to "
                                "make it a scene", root, entry.name)
            continue
        folder = entry
        image = _image_in(folder)
        k = folder / "intrinsics.yaml"
        if image is None and not k.is_file():
            continue
        problem = id_problem(entry.name)
        if problem is not None:  # its name would break the dataset's file names and ImageSets
            bad_names.append(entry.name)
            if warn:
                log.warning("capture folder %s: skipped folder %r: its name is the scene id, "
                            "and %s; rename the folder", root, entry.name, problem)
            continue
        lidar = folder / "lidar.npy"
        radar = folder / "radar.yaml"
        poses = folder / "poses.txt"
        views = folder / "views"
        scene = CaptureScene(
            scene_id=folder.name, folder=str(folder),
            image=None if image is None else str(image),
            intrinsics=str(k) if k.is_file() else (str(shared_k) if shared_k.is_file() else None),
            lidar=str(lidar) if lidar.is_file() else None,
            radar=str(radar) if radar.is_file() else (
                str(shared_radar) if shared_radar.is_file() else None),
            poses=str(poses) if poses.is_file() else None,
            views=tuple(str(v) for v in sorted(views.iterdir()) if v.is_dir()
                        and not v.name.startswith(".")) if views.is_dir() else ())
        scenes.append(scene)
        if warn:
            _note_outside_links([folder] + [None if f is None else Path(f) for f in (
                scene.image, scene.intrinsics, scene.lidar, scene.radar)], root, said)
    if not scenes:
        also = (f"; skipped hidden folder(s) {hidden}: rename them without the leading dot"
                if hidden else "")
        also += (f"; skipped folder(s) {bad_names} whose names cannot be scene ids: rename "
                 "them (printable, no newline, at most "
                 f"{MAX_ID_LENGTH} characters)" if bad_names else "")
        raise ValueError(f"{root}: no scene folders (each needs rgb.png or image.png/.jpg and "
                         f"intrinsics.yaml, here or shared at the top){also}")
    return scenes


def load_capture_frame(scene: CaptureScene):
    """The scene's :class:`~sim2radar.reconstruct.FrameInput` and a note (dropped LiDAR rows).

    Raises
    ------
    ReconstructionInputError (ValueError) naming the file, the field and the fix.
    """
    from sim2radar.camera import CameraIntrinsics
    from sim2radar.reconstruct import FrameInput, ReconstructionInputError
    from sim2radar.reconstruct.inputs import load_image, load_lidar, load_rig_calibration

    if scene.image is None:
        raise ReconstructionInputError(f"{scene.folder}: no image; add rgb.png (or image.png / "
                                       "image.jpg)")
    if scene.intrinsics is None:
        raise ReconstructionInputError(f"{scene.folder}: no intrinsics.yaml (fx, fy, cx, cy, "
                                       "width, height), in the scene folder or the capture folder")
    rgb = load_image(scene.image)
    try:
        k = CameraIntrinsics.from_yaml(scene.intrinsics)
    except (FileNotFoundError, TypeError, ValueError) as exc:
        raise ReconstructionInputError(str(exc)) from None
    rig = load_rig_calibration(scene.intrinsics)
    pts, note = load_lidar(scene.lidar) if scene.lidar else (None, "")
    return FrameInput(rgb, k, pts, name=scene.scene_id, **rig), note


def rigid_transform(value: Any, where: str, field: str) -> np.ndarray:
    """``value`` as a (4, 4) float64 rigid transform ``[R t; 0 0 0 1]``, or a ValueError
    naming ``where`` (the file), ``field`` and the fix.

    Rigid: finite numbers, last row ``0 0 0 1``, ``R`` orthonormal with ``det R = +1``
    (within :data:`RIGID_TOLERANCE`); a singular, scaled, sheared or mirrored matrix is
    refused here, not later as a singular inverse or a failed pose check per frame.
    """
    fix = (f"give {field} as a 4x4 rigid transform [R t; 0 0 0 1] with R a rotation "
           f"(orthonormal, det +1, within {RIGID_TOLERANCE:g}) and t [m]")
    try:
        m = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: {field} is not a 4x4 matrix of numbers ({value!r}); "
                         f"{fix}") from None
    if m.shape != (4, 4):
        raise ValueError(f"{where}: {field} has shape {m.shape}, expected (4, 4) "
                         f"(got {value!r}); {fix}")
    if not np.isfinite(m).all():
        raise ValueError(f"{where}: {field} holds NaN or infinite values; {fix}")
    if not np.allclose(m[3], [0, 0, 0, 1], rtol=0.0, atol=RIGID_TOLERANCE):
        raise ValueError(f"{where}: {field} has last row {m[3].tolist()}, expected "
                         f"[0, 0, 0, 1]; {fix}")
    r = m[:3, :3]
    det = float(np.linalg.det(r))
    off = float(np.abs(r.T @ r - np.eye(3)).max())
    if abs(det) < 1e-9:
        why = "its rotation part is singular (det 0)"
    elif off > RIGID_TOLERANCE:
        why = (f"its rotation part is not orthonormal (max |R^T R - I| = {off:.3g}, det "
               f"{det:.4g}: a scale or shear?)")
    elif abs(det - 1.0) > RIGID_TOLERANCE:
        why = f"its rotation part is a reflection (det {det:.4g}: a left-handed axis?)"
    else:
        return m
    raise ValueError(f"{where}: {field} is not a rigid transform: {why}; {fix}")


def read_poses_txt(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """A scene's ``poses.txt``: view name -> (4, 4) camera (OpenCV) -> world rigid transform
    [m], in file order. One view per line, ``NAME`` then the 16 numbers of the matrix row by
    row; blank lines and ``#`` comments are skipped; ``NAME`` ``.`` is the scene's own view.

    Raises
    ------
    ValueError naming the file, the line and the fix: a line without 17 fields, numbers that
    do not parse, a matrix that is not rigid (:func:`rigid_transform`), a name given twice.
    """
    out: dict[str, np.ndarray] = {}
    fix = ("one view per line: NAME then the camera -> world 4x4 matrix's 16 numbers row by "
           "row, e.g. '. 1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1'")
    for n, raw in enumerate(Path(path).read_text(encoding="utf-8").splitlines(), start=1):
        line = raw.split("#", 1)[0].strip()
        if not line:
            continue
        fields = line.split()
        where = f"{path}, line {n}"
        if len(fields) != 17:
            raise ValueError(f"{where}: {len(fields)} fields, expected 17; {fix}")
        name = fields[0]
        if name in out:
            raise ValueError(f"{where}: view {name!r} is given twice; give each view once")
        try:
            values = [float(v) for v in fields[1:]]
        except ValueError:
            raise ValueError(f"{where}: the matrix holds a value that is not a number "
                             f"({' '.join(fields[1:])!r}); {fix}") from None
        out[name] = rigid_transform(np.reshape(values, (4, 4)), where,
                                    f"the pose of view {name!r}")
    return out


def scene_views(scene: CaptureScene, k: int) -> list[tuple[CaptureScene, np.ndarray]]:
    """The views to fuse into ``scene``'s reconstruction: the first ``k`` views of its
    ``poses.txt`` other than ``.``, each as a :class:`CaptureScene` (its folder under
    ``views/``; intrinsics its own, else the scene's) with ``scene camera <- view camera``
    (4, 4) [m]. Empty for ``k`` 0 or a scene without ``poses.txt`` and ``views/``.

    Raises
    ------
    ValueError naming the file and the fix: ``views/`` without ``poses.txt`` (or the reverse),
    no pose for the scene's own view (``.``), a pose naming no folder of ``views/``.
    """
    if k <= 0 or (scene.poses is None and not scene.views):
        return []
    if scene.poses is None:
        raise ValueError(f"{scene.folder}/views: {len(scene.views)} view(s) but no poses.txt; "
                         "give each view's camera -> world pose in poses.txt (or remove "
                         "views/)")
    poses = read_poses_txt(scene.poses)
    if "." not in poses:
        raise ValueError(f"{scene.poses}: no pose for the scene's own view; add a line "
                         "'. r00 ... 1' (NAME '.' is the scene's rgb image)")
    folders = {Path(v).name: Path(v) for v in scene.views}
    unknown = [name for name in poses if name != "." and name not in folders]
    if unknown:
        raise ValueError(f"{scene.poses}: view(s) {unknown} have no folder under "
                         f"{scene.folder}/views (found: {sorted(folders)})")
    world_from_scene = poses["."]
    out = []
    for name in [n for n in poses if n != "."][:k]:
        folder = folders[name]
        image = _image_in(folder)
        own_k = folder / "intrinsics.yaml"
        lidar = folder / "lidar.npy"
        view = CaptureScene(
            scene_id=f"{scene.scene_id}/{name}", folder=str(folder),
            image=None if image is None else str(image),
            intrinsics=str(own_k) if own_k.is_file() else scene.intrinsics,
            lidar=str(lidar) if lidar.is_file() else None)
        out.append((view, np.linalg.inv(world_from_scene) @ poses[name]))
    return out


def read_radar_yaml(path: str | os.PathLike | None) -> dict:
    """``radar_from_camera`` (4, 4) or None and ``poses`` (P, 3) ``x_m, y_m, yaw_deg`` or None
    of a ``radar.yaml`` (None: neither).

    Raises
    ------
    ValueError naming the file, the field and the fix: an unknown key, a ``radar_from_camera``
    that is not a rigid transform (:func:`rigid_transform`), malformed ``poses``.
    """
    from sim2radar.configio import read_yaml_mapping

    out: dict = {"radar_from_camera": None, "poses": None}
    if path is None:
        return out
    doc = read_yaml_mapping(path, what="radar file")
    unknown = sorted(set(doc) - set(out))
    if unknown:
        raise ValueError(f"{path}: unknown key(s) {unknown}; allowed: radar_from_camera (4x4), "
                         "poses ([[x_m, y_m, yaw_deg], ...])")
    if doc.get("radar_from_camera") is not None:
        out["radar_from_camera"] = rigid_transform(doc["radar_from_camera"], str(path),
                                                   "radar_from_camera")
    if doc.get("poses") is not None:
        try:
            p = np.asarray(doc["poses"], dtype=np.float64)
        except (TypeError, ValueError):
            p = np.zeros((0, 0))
        if p.ndim != 2 or p.shape[1] != 3 or not np.isfinite(p).all() or len(p) == 0:
            raise ValueError(f"{path}: poses must be a list of [x_m, y_m, yaw_deg] rows, got "
                             f"{doc['poses']!r}")
        out["poses"] = p
    return out


# ---------------------------------------------------------------------------------------------
# Radar poses
# ---------------------------------------------------------------------------------------------
def rig_pose(x_m: float, y_m: float, yaw_deg: float, z_m: float = 0.0) -> np.ndarray:
    """(4, 4) rig-to-level transform: moved ``x_m`` forward, ``y_m`` left, ``z_m`` up [m] and
    turned ``yaw_deg`` about z [deg] (counter-clockwise seen from above)."""
    c, s = math.cos(math.radians(yaw_deg)), math.sin(math.radians(yaw_deg))
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:3, 3] = [x_m, y_m, z_m]
    return m


def radar_mount(level_from_camera: np.ndarray, radar_from_camera: np.ndarray | None) -> np.ndarray:
    """(4, 4) radar-to-level transform at the capture pose (identity: the radar at the camera,
    level)."""
    if radar_from_camera is None:
        return np.eye(4)
    return np.asarray(level_from_camera, np.float64) @ np.linalg.inv(radar_from_camera)


def free_space_mask(positions: np.ndarray, first_hit_distance, *, hfov_deg: float,
                    clearance_m: float) -> np.ndarray:
    """Which radar positions (N, 3) [m, level frame] lie in observed free space (module
    docstring): in the camera's horizontal FOV ``hfov_deg`` [deg], a clear line of sight from
    the camera (the origin) reaching ``clearance_m`` beyond them, and ``clearance_m`` to the
    first surface in 8 horizontal directions. ``first_hit_distance(origins, directions)`` [m]
    casts rays in the level frame."""
    p = np.asarray(positions, np.float64).reshape(-1, 3)
    n = len(p)
    if n == 0:
        return np.zeros(0, bool)
    dist = np.linalg.norm(p, axis=1)
    at_camera = dist < 1e-6
    ok = np.ones(n, bool)
    az = np.degrees(np.arctan2(p[:, 1], p[:, 0]))
    ok &= at_camera | ((p[:, 0] > 0) & (np.abs(az) <= hfov_deg / 2))
    sight = ~at_camera & ok
    if sight.any():
        d = p[sight] / dist[sight, None]
        t = np.asarray(first_hit_distance(np.zeros_like(d), d), np.float64)
        ok[np.flatnonzero(sight)] = t >= dist[sight] + clearance_m
    if clearance_m > 0 and ok.any():
        angles = np.radians(np.arange(8) * 45.0)
        dirs = np.stack([np.cos(angles), np.sin(angles), np.zeros(8)], axis=1)
        idx = np.flatnonzero(ok)
        origins = np.repeat(p[idx], 8, axis=0)
        t = np.asarray(first_hit_distance(origins, np.tile(dirs, (len(idx), 1))), np.float64)
        ok[idx] = t.reshape(-1, 8).min(axis=1) >= clearance_m
    return ok


def sample_radar_poses(mount: np.ndarray, first_hit_distance, config: PoseSampling, *,
                       hfov_deg: float, seed: int,
                       given: np.ndarray | None = None) -> tuple[np.ndarray, dict]:
    """Radar poses (F, 4, 4) radar-to-level of one scene, frame 0 at the capture pose.

    ``given`` (P, 3) ``x_m, y_m, yaw_deg`` rig poses replace the sampling (their radar still
    has to be in free space). Sampling draws ``config.max_candidates`` candidates per wanted
    frame with ``numpy.random.default_rng(seed)`` and keeps the first that pass
    :func:`free_space_mask`, in draw order (deterministic for a seed).

    Returns the poses and ``{"candidates", "rejected", "wanted"}``; fewer poses than wanted
    only when the free space is too small (the caller reports it).
    """
    mount = np.asarray(mount, np.float64)
    wanted = int(config.frames) if given is None else len(given)
    if given is not None:
        params = np.column_stack([given[:, 0], given[:, 1], given[:, 2], np.zeros(len(given))])
    else:
        rng = np.random.default_rng(int(seed))
        m = max(0, wanted - 1) * int(config.max_candidates)
        params = np.column_stack([
            rng.uniform(*config.forward_m, m), rng.uniform(*config.lateral_m, m),
            rng.uniform(*config.yaw_deg, m), rng.uniform(*config.height_m, m)])
        params = np.vstack([np.zeros((1, 4)), params])  # frame 0: the capture pose
    poses = np.stack([rig_pose(x, y, yaw, z) @ mount for x, y, yaw, z in params]) \
        if len(params) else np.zeros((0, 4, 4))
    ok = free_space_mask(poses[:, :3, 3], first_hit_distance, hfov_deg=hfov_deg,
                         clearance_m=config.clearance_m)
    if given is None:
        ok[0] = True  # the rig stood there
    keep = np.flatnonzero(ok)[:wanted]
    return poses[keep], {"candidates": int(len(params)), "rejected": int((~ok).sum()),
                         "wanted": wanted}


# ---------------------------------------------------------------------------------------------
# One radar frame
# ---------------------------------------------------------------------------------------------
def capture_frame(radar_scene, door_boxes_level: np.ndarray, pose: np.ndarray, spec: CaptureSpec,
                  *, scene_id: str, frame_index: int, radar_seed: int, scene_seed: int = 0):
    """One radar frame of a reconstructed scene at ``pose`` (radar-to-level, (4, 4)).

    Parameters
    ----------
    radar_scene : RadarScene of the reconstruction's meshes in the level frame.
    door_boxes_level : (M, 7) reconstructed door boxes, level frame [m, rad].
    spec : CaptureSpec — radar, labels, class name.
    radar_seed : seed of this frame's ray jitter, speckle and receiver noise.

    Returns
    -------
    DatasetFrame — geometry ``reconstructed``, labels = the doors the radar sees on the
    reconstructed geometry; no ground truth (empty ``gt_*``).
    """
    import time

    from sim2radar.boxes import transform_boxes
    from sim2radar.factory.frames import DatasetFrame
    from sim2radar.radar import simulate_scene_frame

    pose = np.asarray(pose, np.float64)
    t0 = time.perf_counter()
    rf = simulate_scene_frame(radar_scene, spec.radar, pose, seed=radar_seed)
    sim_s = time.perf_counter() - t0
    boxes = np.asarray(door_boxes_level, np.float32).reshape(-1, 7)
    boxes = transform_boxes(boxes, np.linalg.inv(pose), period="full") if len(boxes) else boxes
    vis = radar_visibility(boxes, scene_ray_caster(radar_scene, pose), spec.view, spec.labels)
    keep = vis >= spec.labels.min_visibility
    boxes, vis = boxes[keep].astype(np.float32), vis[keep].astype(np.float32)
    empty7 = np.zeros((0, 7), np.float32)
    return DatasetFrame(
        frame_id=f"{scene_id}_f{int(frame_index):03d}", world_id=scene_id, seed=int(scene_seed),
        frame_index=int(frame_index), geometry="reconstructed", radar_to_world=pose,
        points=rf.points, doppler_mps=rf.doppler_mps, boxes=boxes,
        box_labels=(spec.class_name,) * len(boxes), label_visibility=vis, gt_boxes=empty7,
        gt_door_index=np.zeros(0, np.int32), gt_points_near=np.zeros(0, np.int32),
        gt_visibility=np.zeros(0, np.float32), n_triangles=radar_scene.n_triangles,
        timings_s={"simulate": sim_s},
        stats={"radar": rf.stats, "radar_seed": int(radar_seed), "source": "capture"},
    )


# ---------------------------------------------------------------------------------------------
# A capture folder from procedural worlds (tests, the README's example)
# ---------------------------------------------------------------------------------------------
#: frames of the trajectory a multi-view capture scene is drawn from (``write_capture_folder``)
VIEW_TRAJECTORY_FRAMES = 8


def write_capture_folder(out_dir: str | os.PathLike, seeds, *, world=None, rig=None,
                         trajectory_seed: int = 0, lidar: bool = True,
                         views: int = 0) -> list[Path]:
    """Write one capture scene per world seed, laid out as a lab's capture folder: the first
    frame of each world's trajectory as ``rgb.png``, ``intrinsics.yaml`` (with the rig
    calibration ``camera_height_m`` and ``up_cam``) and, with ``lidar``, ``lidar.npy``. No
    ground truth goes into the folder. With ``views`` > 0 the scene's image is frame ``views``
    of a trajectory of at least :data:`VIEW_TRAJECTORY_FRAMES` frames (about 2 m apart, as a
    walking capture) and frames ``views - 1 .. 0`` go to ``views/v1 ..`` (most recent first)
    with every frame's camera -> world pose in ``poses.txt``. Returns the scene folders."""
    from sim2radar.worlds import generate_world, render_frame, trajectory
    from sim2radar.worlds.config import make_rig_config, make_world_config

    world_cfg = world if world is not None and not isinstance(world, dict) else \
        make_world_config(world or {})
    rig_cfg = rig if rig is not None and not isinstance(rig, dict) else \
        make_rig_config(rig or {})
    out = []
    for seed in seeds:
        w = generate_world(int(seed), world_cfg)
        n = int(views) + 1 if not views else max(int(views) + 1, VIEW_TRAJECTORY_FRAMES)
        poses = trajectory(w, n, seed=trajectory_seed)
        folder = Path(out_dir) / f"scene_{int(seed):03d}"
        lines = []
        for j in range(int(views), -1, -1):           # the scene's own view first
            frame = render_frame(w, poses[j], rig_cfg, rgb=True, lidar=lidar)
            name = "." if j == int(views) else f"v{int(views) - j}"
            _write_view(folder if name == "." else folder / "views" / name, frame, lidar)
            m = np.asarray(frame.camera_to_world, np.float64)
            lines.append(name + " " + " ".join(f"{v:.9g}" for v in m.ravel()))
        if views:
            (folder / "poses.txt").write_text(
                "# view, then its camera (OpenCV) -> world 4x4, row by row [m]\n"
                + "\n".join(lines) + "\n")
        out.append(folder)
    return out


def _write_view(folder: Path, frame, lidar: bool) -> None:
    import cv2
    import yaml

    folder.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(folder / "rgb.png"), cv2.cvtColor(frame.rgb, cv2.COLOR_RGB2BGR))
    k = frame.intrinsics
    doc = {"fx": float(k.fx), "fy": float(k.fy), "cx": float(k.cx), "cy": float(k.cy),
           "width": int(k.width), "height": int(k.height)}
    rig_cal = frame.rig_calibration
    if "camera_height_m" in rig_cal:
        doc["camera_height_m"] = float(rig_cal["camera_height_m"])
    if "up_cam" in rig_cal:
        doc["up_cam"] = [float(x) for x in rig_cal["up_cam"]]
    (folder / "intrinsics.yaml").write_text(yaml.safe_dump(doc, sort_keys=False))
    if lidar and frame.lidar_points is not None:
        np.save(folder / "lidar.npy", np.asarray(frame.lidar_points, np.float32))
