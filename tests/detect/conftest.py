"""Shared fixtures: a small fast model config and synthetic door frames."""

from __future__ import annotations

import pytest
import torch

from sim2radar.detect.config import DetectConfig


@pytest.fixture(autouse=True)
def _threads():
    """One intra-op thread: on a shared 2-core machine, 2 OpenMP threads contending with other
    processes run these small models ~5x slower than one thread."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def small_config(**sections) -> DetectConfig:
    """0.1 m pillars (64 x 104 grid), slim backbone, fast BN statistics; CPU, no progress bar."""
    base = DetectConfig().with_updates(
        model=dict(voxel_size_m=(0.1, 0.1, 4.0), layer_nums=(1, 1, 1), num_filters=(32, 64, 64),
                   num_upsample_filters=(32, 32, 32), bn_momentum=0.1),
        optimization=dict(batch_size=3, epochs=2),
        runtime=dict(progress=False, device="cpu"),
    )
    return base.with_updates(**sections) if sections else base
