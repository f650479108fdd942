"""The sweep's datasets: content digests, domain labels (undeclared unless dataset.json
declares one), disjoint worlds, column handling, intensity matching fitted on each run's real
subset only."""

from __future__ import annotations

import numpy as np
import pytest

from sim2radar.datasets import DatasetError, Frame, write_dataset, write_metadata
from sim2radar.experiment import load_profile, plan_sweep
from sim2radar.experiment.data import (
    check_disjoint_worlds,
    dataset_digest,
    fit_subset_intensity_match,
    open_domain,
    with_intensity,
    world_of_frame,
)
from sim2radar.experiment.plan import ids_digest
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
    assert real.domain == "undeclared" and not real.is_proxy      # no dataset.json: not guessed
    assert real.metadata["domain"] == real.describe()["domain"] == "undeclared"
    write_metadata(real.root, {"radar": "some radar"})             # a file, but no domain
    assert open_domain(real.root, "real").domain == "undeclared"
    write_metadata(real.root, {"domain": "measured"})              # declared measured
    assert open_domain(real.root, "real").domain == "measured"
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
    (real_root / "dataset.json").unlink()                          # undeclared: not checked
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


def _real_frames(n=40, seed=3):
    """Real frames whose intensity level rises with the frame index: frame i's intensities
    ~ N(-60 + i, 1) dB, so the subset a match is fitted on shows in its target quantiles."""
    rng = np.random.default_rng(seed)
    return [Frame(f"world_{i:06d}_f000",
                  np.column_stack([rng.normal(0, 1, (30, 3)), rng.normal(-60.0 + i, 1.0, 30)])
                  .astype(np.float32), np.zeros((0, 7), np.float32), ()) for i in range(n)]


def test_intensity_match_is_fitted_on_each_runs_real_subset_only():
    """The audit's case: one match fitted on every real train frame served every fraction.
    Fitted per run, the 5 % arm sees only its own 2 frames' intensities, matches differ per
    fraction, and frames outside the subset do not move the fit."""
    real = _real_frames()
    sim = [Frame("s0", np.column_stack([np.zeros((500, 3)), np.random.default_rng(1)
                                         .normal(-20, 5, 500)]).astype(np.float32),
                 np.zeros((0, 7), np.float32), ())]
    prof = load_profile("smoke")
    prof = type(prof).model_validate({**prof.model_dump(), "fractions": (0.05, 0.25, 1.0),
                                      "trials": 1})
    _, runs = plan_sweep(prof, [f.frame_id for f in real])
    by_fraction = {r.fraction: r.train_ids for r in runs if r.condition == "sim-pretrain"}
    fits = {f: fit_subset_intensity_match(sim, real, ids) for f, ids in by_fraction.items()}
    for f, fit in fits.items():
        ids = by_fraction[f]
        target = np.concatenate([fr.points[:, 3] for fr in real if fr.frame_id in ids])
        np.testing.assert_allclose(fit.match.target_quantiles_db,
                                   np.quantile(target.astype(np.float64),
                                               fit.match.probabilities))
        assert fit.match.n_target == 30 * len(ids) and fit.subset_ids == tuple(ids)
        doc = fit.to_dict()
        assert doc["n_real_frames"] == len(ids) and doc["subset_ids_digest"] == ids_digest(ids)
        assert doc["fitted_on"].startswith(f"{len(ids)} frames of the run's real fine-tuning")
    assert [len(by_fraction[f]) for f in (0.05, 0.25, 1.0)] == [2, 10, 40]
    medians = {f: float(np.median(fit.match.target_quantiles_db)) for f, fit in fits.items()}
    assert len({round(m, 3) for m in medians.values()}) == 3          # a different fit each
    assert abs(medians[1.0] - (-60 + 19.5)) < 1.0                        # all 40 frames
    # sim frames mapped with the 5 % fit land on the 5 % subset's level, not the split's
    sub5 = [int(i.split("_")[1]) for i in by_fraction[0.05]]
    mapped = with_intensity(sim, fits[0.05].match)[0].points[:, 3]
    assert abs(np.median(mapped) - (-60 + np.mean(sub5))) < 1.5
    # frames outside the subset do not change the fit
    moved = [Frame(fr.frame_id, fr.points + np.array([0, 0, 0, 30.0], np.float32), fr.boxes,
                   fr.names) if fr.frame_id not in by_fraction[0.05] else fr for fr in real]
    again = fit_subset_intensity_match(sim, moved, by_fraction[0.05])
    np.testing.assert_array_equal(again.match.target_quantiles_db,
                                  fits[0.05].match.target_quantiles_db)
    with pytest.raises(ValueError, match="not among the real frames"):
        fit_subset_intensity_match(sim, real[:5], by_fraction[1.0])
    with pytest.raises(ValueError, match="empty"):
        fit_subset_intensity_match(sim, real, [])
