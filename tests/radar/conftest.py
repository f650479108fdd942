"""Shared radar-test fixtures: the ti-mmwcas preset and small metal/wood targets."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.mesh import box_mesh
from sim2radar.radar import load_radar_config


@pytest.fixture(scope="session")
def mmwcas():
    return load_radar_config("ti-mmwcas")


def facing_plate(x, y=0.0, z=0.0, size=1.0, material="metal", tilt_rad=0.0, name="plate"):
    """A thin square plate whose front face is at distance sqrt(x^2+y^2) facing the radar
    (rotated by an extra ``tilt_rad`` about z)."""
    heading = float(np.arctan2(y, x)) + tilt_rad
    thick = 0.01
    c = np.array([x, y, z], dtype=float)
    c[:2] += 0.5 * thick * np.array([np.cos(np.arctan2(y, x)), np.sin(np.arctan2(y, x))])
    return box_mesh(c, [thick, size, size], heading, material=material, name=name)


def dihedral(x_crease, size=1.0, material="metal"):
    """Two plates meeting at a vertical crease at (x_crease, 0, 0), each at 45 deg to the
    boresight, opening toward the radar (a dihedral corner reflector)."""
    half = size / 2 * np.sqrt(0.5)
    return [
        box_mesh(
            [x_crease - half, half, 0.0],
            [0.005, size, size],
            np.pi / 4,
            material=material,
            name="left",
        ),
        box_mesh(
            [x_crease - half, -half, 0.0],
            [0.005, size, size],
            -np.pi / 4,
            material=material,
            name="right",
        ),
    ]
