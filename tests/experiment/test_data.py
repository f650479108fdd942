"""The sweep's datasets: content digests, domain labels, disjoint worlds, column handling."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.datasets import DatasetError, Frame, write_dataset, write_metadata
from sim2radar.experiment.data import (
    check_disjoint_worlds,
    dataset_digest,
    open_domain,
    with_intensity,
    world_of_frame,
)
from sim2radar.radar.intensity import fit_intensity_match


def _dataset(root, worlds, columns=4, seed=0):
    rng = np.random.default_rng(seed)
    frames, splits = [], {"train": [], "val": [], "test": []}
    for i, w in enumerate(worlds):
        for k in range(2):
            fid = f"world_{w:06d}_f{k:03d}"
            pts = rng.normal(0, 1, (50, columns)).astype(np.float32)
            frames.append(Frame(fid, pts, np.array([[2, 0, 0, 1, 0.2, 2, 0]], np.float32),
                                ("door",)))
            splits[("train", "val", "test")[i % 3]].append(fid)
    write_dataset(root, frames, splits)
    return root


def test_digest_follows_content_not_export_time(tmp_path):
    a = _dataset(tmp_path / "a", [1, 2, 3])
    b = _dataset(tmp_path / "b", [1, 2, 3])
    assert dataset_digest(a) == dataset_digest(b)                 # same bytes, same key
    write_metadata(a, {"domain": "measured", "exported_at": "now"})
    assert dataset_digest(a) == dataset_digest(b)                 # metadata is not content
    pts = np.load(a / "points" / "world_000001_f000.npy")
    pts[0, 0] += 0.01
    np.save(a / "points" / "world_000001_f000.npy", pts)
    assert dataset_digest(a) != dataset_digest(b)                 # one point moved: new key


def test_domain_label_and_splits(tmp_path):
    real = open_domain(_dataset(tmp_path / "r", [1, 2, 3]), "real")
    assert real.domain == "measured" and not real.is_proxy        # no dataset.json
    write_metadata(real.root, {"domain": "proxy-real (reference radar simulation)"})
    proxy = open_domain(real.root, "real")
    assert proxy.is_proxy and proxy.splits["train"] == ["world_000001_f000", "world_000001_f001"]
    assert len(proxy.ids()) == 6


def test_proxy_real_must_not_share_worlds_with_the_sim(tmp_path):
    sim = open_domain(_dataset(tmp_path / "s", [1, 2, 3]), "sim")
    real_root = _dataset(tmp_path / "r", [3, 4, 5])
    write_metadata(real_root, {"domain": "proxy-real (reference radar simulation)"})
    with pytest.raises(DatasetError, match="share 1 world.*world_000003"):
        check_disjoint_worlds(sim, open_domain(real_root, "real"))
    disjoint = _dataset(tmp_path / "d", [7, 8, 9])
    write_metadata(disjoint, {"domain": "proxy-real (reference radar simulation)"})
    check_disjoint_worlds(sim, open_domain(disjoint, "real"))     # fine
    (real_root / "dataset.json").unlink()                          # measured: not checked
    check_disjoint_worlds(sim, open_domain(real_root, "real"))
    assert world_of_frame("world_000003_f012") == "world_000003"
    assert world_of_frame("ifr_scene_7") is None


def test_doppler_column_is_dropped_for_a_four_feature_model(tmp_path):
    ds = open_domain(_dataset(tmp_path / "r", [1, 2, 3], columns=5), "real")
    frames = ds.frames(ds.ids(["train"]), 4, ("door",))
    assert all(f.points.shape[1] == 4 for f in frames)
    with pytest.raises(DatasetError, match="columns"):
        open_domain(_dataset(tmp_path / "x", [1, 2, 3], columns=3), "real").frames(
            ["world_000001_f000"], 4, ("door",))


def test_intensity_matching_changes_only_the_intensity_column(tmp_path):
    ds = open_domain(_dataset(tmp_path / "r", [1, 2, 3]), "real")
    frames = ds.frames(ds.ids(), 4, ("door",))
    match = fit_intensity_match(np.concatenate([f.points[:, 3] for f in frames]),
                                np.random.default_rng(5).normal(-40, 3, 5000))
    out = with_intensity(frames, match)
    for a, b in zip(frames, out, strict=True):
        np.testing.assert_array_equal(a.points[:, :3], b.points[:, :3])
        assert abs(np.median(b.points[:, 3]) + 40) < 2.0
