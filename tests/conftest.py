"""Shared test configuration: CPU by default, Prefect state kept inside the test tmp dir."""

from __future__ import annotations

import os

import pytest

# Keep Prefect's state out of ~ and make it quiet; tests never need a running server.
os.environ.setdefault("PREFECT_SERVER_ANALYTICS_ENABLED", "false")
os.environ.setdefault("PREFECT_LOGGING_LEVEL", "WARNING")


def pytest_collection_modifyitems(config, items):
    from sim2radar.hardware import has_cuda

    if has_cuda():
        return
    skip = pytest.mark.skip(reason="needs a CUDA GPU")
    for item in items:
        if "gpu" in item.keywords:
            item.add_marker(skip)
