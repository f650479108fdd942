import pytest

from sim2radar.registry import Registry, UnknownBackendError


def test_unknown_name_lists_known_ones():
    reg = Registry("depth")

    @reg.register("lidar")
    class Lidar:
        pass

    assert reg.get("lidar") is Lidar and "lidar" in reg
    with pytest.raises(UnknownBackendError, match="known backends: lidar"):
        reg.get("moge")
