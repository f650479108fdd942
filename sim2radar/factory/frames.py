"""One labelled radar frame of the factory (any geometry, any radar fidelity) and its figures."""

from __future__ import annotations

import dataclasses

import numpy as np

from sim2radar.boxes import points_in_boxes

__all__ = ["DatasetFrame", "NEAR_BOX_MARGIN_M", "points_near_boxes"]

#: Extra margin around a ground-truth box when counting radar points "in or near" it [m].
NEAR_BOX_MARGIN_M = 0.25


@dataclasses.dataclass(frozen=True, eq=False)
class DatasetFrame:
    """One decoded ``dataset_frames`` row.

    Attributes
    ----------
    frame_id, world_id : str; seed, frame_index : int
    geometry : str — ``ground_truth`` (the world's meshes) or ``reconstructed`` (from RGB).
    radar_to_world : (4, 4) float64 [m]
    points : (N, 4) float32 — x, y, z [m] radar frame, intensity [dB]
    doppler_mps : (N,) float32 — radial velocity of each point [m/s] (0 for the ray tracer,
        which has no Doppler; measured by the signal-level radar).
    boxes : (M, 7) float32 — labels ``x y z dx dy dz heading`` [m, rad], radar frame
    box_labels : tuple[str, ...]
    label_visibility : (M,) float32 — fraction of each label's doorway the radar sees
        (:func:`sim2radar.factory.labels.radar_visibility`) in the geometry it was simulated on.
    gt_boxes : (G, 7) float32 — ground-truth doors the radar sees, radar frame
    gt_door_index : (G,) int32; gt_points_near : (G,) int32
    gt_visibility : (G,) float32 — their visibility on the world's geometry.
    n_triangles : int; timings_s : dict [s]; stats : dict
    surface_offset_m : (N,) float32 or None — each point's range minus the distance to the
        first surface of the *world's* geometry along its ray [m] (``inf``: none;
        :func:`sim2radar.evaluate.fidelity.surface_offsets`); None where no true geometry is
        known (capture folders).
    """

    frame_id: str
    world_id: str
    seed: int
    frame_index: int
    geometry: str
    radar_to_world: np.ndarray
    points: np.ndarray
    doppler_mps: np.ndarray
    boxes: np.ndarray
    box_labels: tuple[str, ...]
    label_visibility: np.ndarray
    gt_boxes: np.ndarray
    gt_door_index: np.ndarray
    gt_points_near: np.ndarray
    gt_visibility: np.ndarray
    n_triangles: int
    timings_s: dict
    stats: dict
    surface_offset_m: np.ndarray | None = None

    @property
    def points_with_doppler(self) -> np.ndarray:
        """(N, 5) float32 — x, y, z [m], intensity [dB], doppler [m/s]."""
        return np.concatenate([self.points, self.doppler_mps.reshape(-1, 1)], axis=1).astype(
            np.float32)


def points_near_boxes(points: np.ndarray, boxes: np.ndarray,
                      margin_m: float = NEAR_BOX_MARGIN_M) -> np.ndarray:
    """(M,) int32 — radar points inside each box grown by ``margin_m`` on every side [m]."""
    return points_in_boxes(points, boxes, margin_m).sum(axis=0).astype(np.int32)
