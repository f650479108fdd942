"""Shared fixtures for world tests: small images, few samples, cached worlds."""

from __future__ import annotations

import pytest

from sim2radar.worlds import RigConfig, generate_world, render_frame, trajectory
from tests.worlds._helpers import SMALL_RIG


@pytest.fixture(scope="session")
def small_rig() -> RigConfig:
    return SMALL_RIG


@pytest.fixture(scope="session")
def world3():
    return generate_world(3)


@pytest.fixture(scope="session")
def frames3(world3):
    poses = trajectory(world3, 3, seed=0)
    return [render_frame(world3, p, SMALL_RIG) for p in poses]
