"""Issue #33, probe 3: hostile inputs are refused before they cost memory — a "billion laughs"
YAML (a generate config, a radar config, a capture's intrinsics.yaml), an image declaring
20000 x 20000 pixels, and counts or radar sizes past their bounds — each in one line naming
the file or option and the bound. Runs that could allocate are subprocesses under a 3 GiB
address-space limit (``resource.setrlimit``; 10 GiB where a scene is simulated), so a regression fails the test instead of the
machine."""

from __future__ import annotations

import os
import resource
import struct
import subprocess
import sys
import zlib
from pathlib import Path

import numpy as np
import pytest

LAUGHS = """\
a: &a ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]
b: &b [*a,*a,*a,*a,*a,*a,*a,*a,*a]
c: &c [*b,*b,*b,*b,*b,*b,*b,*b,*b]
d: &d [*c,*c,*c,*c,*c,*c,*c,*c,*c]
e: &e [*d,*d,*d,*d,*d,*d,*d,*d,*d]
f: &f [*e,*e,*e,*e,*e,*e,*e,*e,*e]
g: &g [*f,*f,*f,*f,*f,*f,*f,*f,*f]
h: &h [*g,*g,*g,*g,*g,*g,*g,*g,*g]
"""


def _bounded(*args: str, timeout: float = 240.0, gib: int = 3) -> subprocess.CompletedProcess:
    def limit():
        resource.setrlimit(resource.RLIMIT_AS, (gib << 30, gib << 30))

    code = "import sys; from sim2radar.cli import main; sys.argv[0] = 'sim2radar'; main()"
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True,
                          text=True, preexec_fn=limit, timeout=timeout,
                          env={**os.environ, "COLUMNS": "300"})


def test_load_yaml_refuses_a_bomb_without_expanding_it(monkeypatch):
    import time

    import yaml

    from sim2radar import configio
    from sim2radar.configio import MAX_YAML_VALUES, YamlTooLargeError, load_yaml

    t0 = time.perf_counter()
    with pytest.raises(YamlTooLargeError, match="billion laughs"):
        load_yaml(LAUGHS + "x: [*h,*h,*h,*h,*h,*h,*h,*h,*h]\n")
    assert time.perf_counter() - t0 < 5.0   # counted, not expanded (10^9 values)
    assert isinstance(YamlTooLargeError("x"), yaml.YAMLError)
    # shared anchors that stay small are fine, and counted per reference
    doc = load_yaml("a: &a [1, 2, 3]\nb: *a\nc: *a\n")
    assert doc == {"a": [1, 2, 3], "b": [1, 2, 3], "c": [1, 2, 3]}
    # a plain list over the limit too (a smaller limit: parsing 200,000 values takes ~10 s)
    assert MAX_YAML_VALUES == 200_000
    monkeypatch.setattr(configio, "MAX_YAML_VALUES", 1_000)
    load_yaml("x: [" + ", ".join(["1"] * 990) + "]\n")
    with pytest.raises(YamlTooLargeError):
        load_yaml("x: [" + ", ".join(["1"] * 1_010) + "]\n")


@pytest.mark.parametrize("where", ["generate", "radar"])
def test_a_yaml_bomb_config_is_one_line_under_a_memory_limit(tmp_path, where):
    bomb = tmp_path / "bomb.yaml"
    if where == "generate":
        bomb.write_text(LAUGHS + "frames_per_world: [*h,*h,*h,*h,*h,*h,*h,*h,*h]\n")
        args = ["generate", "--config", str(bomb)]
    else:
        bomb.write_text(LAUGHS + "name: [*h,*h,*h,*h,*h,*h,*h,*h,*h]\n")
        args = ["generate", "--radar", str(bomb)]
    res = _bounded(*args, "--no-prefect", "--out", str(tmp_path / "store"))
    assert res.returncode == 2, res.stdout + res.stderr
    out = res.stdout + res.stderr
    assert str(bomb) in out and "billion laughs" in out
    assert "Traceback" not in out and len(out) < 2000


def _png_header(width: int, height: int) -> bytes:
    """A PNG whose header declares ``width`` x ``height`` (its data is one empty row)."""
    def chunk(kind: bytes, data: bytes) -> bytes:
        return (struct.pack(">I", len(data)) + kind + data
                + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF))

    ihdr = struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr)
            + chunk(b"IDAT", zlib.compress(b"\0" * (3 * width + 1))) + chunk(b"IEND", b""))


def test_image_size_reads_png_jpeg_and_bmp_headers(tmp_path):
    import cv2

    from sim2radar.reconstruct.inputs import image_size

    img = np.random.default_rng(0).integers(0, 255, (37, 53, 3), np.uint8)
    for ext in ("png", "jpg", "bmp"):
        cv2.imwrite(str(tmp_path / f"i.{ext}"), img)
        assert image_size(tmp_path / f"i.{ext}") == (53, 37), ext
    (tmp_path / "i.txt").write_text("not an image")
    assert image_size(tmp_path / "i.txt") is None


def test_a_huge_image_is_refused_from_its_header(tmp_path, monkeypatch):
    from sim2radar.reconstruct import ReconstructionInputError
    from sim2radar.reconstruct.inputs import load_image

    big = tmp_path / "rgb.png"
    big.write_bytes(_png_header(20000, 20000))
    with pytest.raises(ReconstructionInputError, match=r"20000 x 20000 = 400 MP, more than the "
                                                       r"25 MP.*SIM2RADAR_MAX_IMAGE_PIXELS"):
        load_image(big)
    monkeypatch.setenv("SIM2RADAR_MAX_IMAGE_PIXELS", "1e3")
    small = tmp_path / "small.png"
    small.write_bytes(_png_header(40, 30))
    with pytest.raises(ReconstructionInputError, match="more than the 0 MP"):
        load_image(small)


def test_a_capture_with_a_huge_image_or_a_bomb_intrinsics_fails_alone(tmp_path):
    """Through `generate --captures` under a memory limit: the 20000 x 20000 scene and the
    scene whose intrinsics.yaml is a bomb each fail in one line; the good scene finishes
    (10 GiB of address space: the LLVM ray tracer reserves more than it uses; the image alone
    would need ~24 GB)."""
    from typer.testing import CliRunner

    from sim2radar.cli import app

    caps = tmp_path / "caps"
    res = CliRunner().invoke(app, ["worlds", "captures", "--out", str(caps), "--worlds", "1",
                                   "--first-seed", "4", "--width", "80", "--height", "60",
                                   "--spp", "1"])
    assert res.exit_code == 0, res.output
    import shutil

    good = caps / "scene_004"
    for name in ("big", "bomb"):
        shutil.copytree(good, caps / name)
    (caps / "big" / "rgb.png").write_bytes(_png_header(20000, 20000))
    (caps / "bomb" / "intrinsics.yaml").write_text(
        LAUGHS + "fx: [*h,*h,*h,*h,*h,*h,*h,*h,*h]\n")
    res = _bounded("generate", "--captures", str(caps), "--no-prefect", "--frames", "1",
                   "--no-png", "--out", str(tmp_path / "store"), timeout=400, gib=10)
    out = res.stdout + res.stderr
    assert res.returncode == 1, out  # two scenes failed (recorded), the third finished
    assert "1 computed" in out and "2 failed" in out, out
    assert "400 MP" in out and "billion laughs" in out
    assert "Traceback" not in out


@pytest.mark.parametrize("args, words", [
    (["generate", "--worlds", "1000000000"], "--worlds must be between 1 and 100000"),
    (["generate", "--frames", "1000000000"], "--frames must be between 1 and 1000"),
    (["worlds", "generate", "--worlds", "1000000000"], "less than or equal to 100000"),
    (["reference", "--frames", "1000000000"], "less than or equal to 1000"),
])
def test_counts_past_their_bound_are_refused_before_any_work(tmp_path, args, words):
    res = _bounded(*args, "--out", str(tmp_path / "store"), timeout=120)
    out = " ".join((res.stdout + res.stderr).replace("│", " ").split())
    assert res.returncode == 2, out
    assert words in out, out
    assert not (tmp_path / "store").exists()


def test_a_radar_config_whose_cube_cannot_fit_is_refused(tmp_path):
    from sim2radar.radar.config import RadarConfigError, load_radar_config

    with pytest.raises(RadarConfigError, match=r"n_chirps \(1000000000\).*GiB ADC cube per "
                                               r"frame, more than the 2 GiB bound"):
        load_radar_config("ti-mmwcas", n_chirps=10**9)
    assert load_radar_config("ti-mmwcas", n_chirps=256).n_chirps == 256
    path = Path(tmp_path / "r.yaml")
    assert not path.exists()
