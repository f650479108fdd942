"""Seed recipes of the factory: one function per derived seed, called everywhere it is needed."""

from __future__ import annotations

import numpy as np

__all__ = ["frame_seed", "frame_speed", "pose_seed", "scene_seed", "scene_file_frame_seed"]


def frame_seed(run_seed: int, world_seed: int, frame_index: int) -> int:
    """Radar seed (ray jitter, speckle, receiver noise) of one world frame.

    The same for every geometry and radar of that frame, so frames compare fairly; derived with
    :class:`numpy.random.SeedSequence` from (run seed, world seed, frame index).
    """
    ss = np.random.SeedSequence([int(run_seed), int(world_seed), int(frame_index), 0x5EED])
    return int(ss.generate_state(1)[0])


def frame_speed(speed_mps: tuple[float, float], run_seed: int, world_seed: int,
                frame_index: int) -> float:
    """The rig's speed [m/s] while one world frame is taken: uniform in ``speed_mps`` (min,
    max), from (run seed, world seed, frame index) with its own stream (not the radar seed's)."""
    lo, hi = float(speed_mps[0]), float(speed_mps[1])
    if hi <= 0.0:
        return 0.0
    rng = np.random.default_rng([int(run_seed), int(world_seed), int(frame_index), 0x5BEED])
    return float(rng.uniform(lo, hi)) if hi > lo else lo


def scene_seed(digest: str) -> int:
    """A capture scene's seed from the content digest of its inputs (hex string): the same
    images give the same seed wherever and whenever they are processed."""
    return int(str(digest)[:15], 16)


def pose_seed(run_seed: int, scene_seed_: int) -> int:
    """Seed of the radar-pose sampling of one capture scene, from (run seed, scene seed)."""
    ss = np.random.SeedSequence([int(run_seed), int(scene_seed_), 0x9053])
    return int(ss.generate_state(1)[0])


def scene_file_frame_seed(run_seed: int, scene_key: str, frame_index: int) -> int:
    """Radar seed of one pose of a scene file (``sim2radar simulate``), from (run seed, the
    scene's content key (hex), frame index)."""
    entropy = [int(run_seed), int(scene_key[:8], 16), int(frame_index)]
    return int(np.random.SeedSequence(entropy).generate_state(1)[0])
