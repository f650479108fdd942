"""Simulated-data fidelity: where the points of each domain are, what the doors give, how good
the door labels are, and whether a pre-training on the sim learns anything (issue #29).

The same frames in every domain: the held-out validation worlds
(``configs/evaluation/heldout_worlds.yaml``, fixed before the door work and never tuned on),
``W`` worlds x ``F`` frames along the rig's trajectory (run seed 0), simulated

* ``gt`` — the ray-traced sim on the worlds' ground-truth meshes;
* ``rec`` — the ray-traced sim on meshes reconstructed from the frames' RGB + LiDAR (the
  paper's pipeline), labelled with its reconstructed door boxes;
* ``ref`` — the reference radar (TI cascade, signal level, moving rig) on the ground truth.

Per domain it prints points per frame (median), the share of points more than 1 m behind the
first true surface along their ray and beyond 0.85 R_max (:mod:`sim2radar.evaluate.fidelity`),
points inside a door label box (median; share of boxes with none; with < 5), the azimuth the
points cover (1-99 %), and for the labels: recall / precision against the ground-truth doors
the radar sees (3D IoU 0.3) and the matched labels' width / depth error.

Pre-training learnability: the ``study`` profile's pre-training (its detector, lr, batch and
its step budget: 20 epochs of its 270-frame sim set = 680 steps) on sim frames of ``T``
training worlds (seeds 0..T-1) of each geometry, intensities matched to the proxy-real train
split, then checked (:func:`sim2radar.experiment.learnability.check_pretraining`): 3D AP
(R40, IoU 0.3) on the held-out worlds' sim frames and zero-shot on the proxy-real validation
split (reference radar on worlds 100000.., disjoint).

    python -m benchmarks fidelity
    SIM2RADAR_BENCH_FIDELITY="worlds=2 frames=2 train_worlds=4 real_worlds=4" \\
        python -m benchmarks fidelity                   # a small run
    SIM2RADAR_BENCH_FIDELITY_OUT=out/bench_fidelity     # where the store and exports go
                                                        # (cached: a rerun only measures)
"""

from __future__ import annotations

import math
import os
import time
from pathlib import Path

import numpy as np

#: Sizes (override with SIM2RADAR_BENCH_FIDELITY="key=value ...").
DEFAULTS = {"worlds": 6, "frames": 4, "train_worlds": 24, "train_frames": 4,
            "real_worlds": 12, "real_frames": 4, "learn": 1, "seed": 0}
#: The study profile's pre-training budget in optimiser steps: 20 epochs x 270 frames / 8.
STUDY_PRETRAIN_STEPS = 680
REAL_FIRST_SEED = 100000
TRAIN_FIRST_SEED = 0


def _sizes() -> dict[str, int]:
    out = dict(DEFAULTS)
    for item in os.environ.get("SIM2RADAR_BENCH_FIDELITY", "").split():
        key, _, value = item.partition("=")
        if key not in out:
            raise SystemExit(f"SIM2RADAR_BENCH_FIDELITY: unknown key {key!r}; known: {sorted(out)}")
        out[key] = int(value)
    return out


def heldout_seeds(n: int) -> list[int]:
    """The first ``n`` held-out validation world seeds."""
    from sim2radar.evaluate.fidelity import heldout_world_seeds

    seeds = heldout_world_seeds()
    if n > len(seeds):
        raise SystemExit(f"only {len(seeds)} held-out worlds are fixed; asked for {n}")
    return seeds[:n]


def _generate(seeds, frames, geometry, radar, store, name, export, *, splits=None,
              reference=False, seed=0):
    """One dataset through the ``generate`` job's driver, worlds one after another in this
    process (:class:`~sim2radar.tasks.runner.PlainRunner`), exported to ``export``."""
    from sim2radar.factory.spec import DatasetSpec
    from sim2radar.tasks.generate import GenerateRequest, generate_dataset
    from sim2radar.tasks.runner import PlainRunner

    where = {"seeds": list(seeds), "store": os.fspath(store), "dataset": name,
             "export_dir": os.fspath(export), "splits": splits}
    if reference:
        from sim2radar.factory.reference import DOMAIN_LABEL

        spec = DatasetSpec(frames_per_world=frames, geometry="ground_truth", radar=radar,
                           seed=seed, render_rgb=False, motion={"speed_mps": [0.5, 1.5]})
        request = GenerateRequest(spec=spec, **where, export_doppler=True, domain=DOMAIN_LABEL)
    else:
        spec = DatasetSpec(frames_per_world=frames, geometry=geometry, radar=radar, seed=seed)
        request = GenerateRequest(spec=spec, **where)
    return generate_dataset(request, PlainRunner())


def _labels(root: Path, fid: str) -> np.ndarray:
    p = root / "labels" / f"{fid}.txt"
    rows = [line.split() for line in p.read_text().splitlines() if line.strip()] \
        if p.is_file() else []
    return np.array([[float(v) for v in r[:7]] for r in rows], np.float64).reshape(-1, 7)


def _pairs(pred: np.ndarray, gt: np.ndarray) -> list[tuple[int, int]]:
    from sim2radar.evaluate.reconstruction import match_boxes

    return list(match_boxes(pred, gt, 0.3)["pairs"])


def measure_domain(root: Path, gt_root: Path, frames_per_world: int, seed: int = 0) -> dict:
    """The fidelity figures of one exported domain (module doc), its points' surface offsets
    measured on the worlds' meshes from the trajectory's radar poses; labels compared with the
    ground-truth export's (the doors the radar sees)."""
    from sim2radar.datasets import OpenPCDetDataset
    from sim2radar.evaluate.fidelity import (
        FidelityCounts,
        azimuth_coverage_deg,
        box_size_errors,
        points_per_box,
        surface_offsets,
    )
    from sim2radar.factory.labels import scene_ray_caster
    from sim2radar.radar import RadarScene, load_radar_config
    from sim2radar.worlds import RigConfig, generate_world, render_frame, trajectory

    ds = OpenPCDetDataset(root)
    ids = [i for s in ds.splits() for i in ds.split_ids(s)]
    cache: dict[int, tuple] = {}
    offsets, ranges, points, n_pts, inside = [], [], [], [], []
    tp = n_pred = n_gt = 0
    errors = []
    for fid in sorted(ids):
        world_seed, k = int(fid.split("_")[1]), int(fid.split("_f")[1])
        if world_seed not in cache:
            world = generate_world(world_seed)
            poses = trajectory(world, frames_per_world, seed=seed)
            cache = {world_seed: (RadarScene(list(world.meshes)), world, poses)}
        scene, world, poses = cache[world_seed]
        pose = render_frame(world, poses[k], RigConfig(), rgb=False, lidar=False).radar_to_world
        pts = np.asarray(ds.frame(fid).points, np.float64)
        offsets.append(surface_offsets(pts, scene_ray_caster(scene, pose)))
        ranges.append(np.linalg.norm(pts[:, :3], axis=1))
        points.append(pts)
        n_pts.append(len(pts))
        labels, gt = _labels(root, fid), _labels(gt_root, fid)
        inside += points_per_box(pts, labels).tolist()
        pairs = _pairs(labels, gt)
        tp, n_pred, n_gt = tp + len(pairs), n_pred + len(labels), n_gt + len(gt)
        errors.append(box_size_errors(labels, gt, pairs))
    counts = FidelityCounts.of(offsets, ranges, load_radar_config("ti-mmwcas").max_range_m)
    lo, hi = azimuth_coverage_deg(points)
    err = np.concatenate(errors) if errors else np.zeros((0, 4))
    inside_a = np.asarray(inside)
    return {
        "frames": len(ids), "points_per_frame": float(np.median(n_pts)) if n_pts else math.nan,
        "behind_share": counts.behind_share, "beyond_share": counts.beyond_share,
        "points_per_label": float(np.median(inside_a)) if len(inside_a) else math.nan,
        "labels_empty": float(np.mean(inside_a == 0)) if len(inside_a) else math.nan,
        "labels_under_5": float(np.mean(inside_a < 5)) if len(inside_a) else math.nan,
        "azimuth_1_99_deg": (lo, hi),
        "label_recall": tp / n_gt if n_gt else math.nan,
        "label_precision": tp / n_pred if n_pred else math.nan,
        "label_width_error_m": float(np.abs(err[:, 0]).mean()) if len(err) else math.nan,
        "label_depth_error_m": float(np.abs(err[:, 1]).mean()) if len(err) else math.nan,
        "labels": int(n_pred), "gt_doors": int(n_gt),
    }


def learnability(out: Path, sim_train: Path, sim_heldout: Path, real: Path, tag: str) -> dict:
    """The study profile's pre-training on ``sim_train`` (its step budget), checked on the
    held-out sim frames and zero-shot on the proxy-real validation split."""
    from sim2radar.experiment.data import fit_subset_intensity_match, open_domain, with_intensity
    from sim2radar.experiment.learnability import check_pretraining
    from sim2radar.experiment.profiles import load_profile
    from sim2radar.experiment.runner import pretrain_encoder

    profile = load_profile("study")
    cfg = profile.detector_config("pretrain")
    nfeat, classes = cfg.model.num_point_features, cfg.model.class_names
    sim_d, held_d, real_d = (open_domain(sim_train, "sim"), open_domain(sim_heldout, "heldout"),
                             open_domain(real, "real"))
    sim = sim_d.frames(sim_d.ids(), nfeat, classes)
    held = held_d.frames(held_d.ids(), nfeat, classes)
    real_train = real_d.frames(real_d.ids(["train"]), nfeat, classes)
    real_val = real_d.frames(real_d.ids(["val"]), nfeat, classes)
    match = fit_subset_intensity_match(sim, real_train, [f.frame_id for f in real_train]).match
    sim, held = with_intensity(sim, match), with_intensity(held, match)
    epochs = max(1, math.ceil(STUDY_PRETRAIN_STEPS * profile.batch_size / len(sim)))
    t0 = time.perf_counter()
    # the folder is keyed by the training data's digest: pretrain_encoder reuses a finished
    # folder, and a rerun on regenerated frames must train anew
    ckpt = pretrain_encoder(cfg, sim, out / f"pretrain_{tag}_{sim_d.key[:12]}", seed=0,
                            epochs=epochs)
    train_s = time.perf_counter() - t0
    check = check_pretraining(ckpt, held, real_val)
    train_check = check_pretraining(ckpt, sim, [])
    return {"sim_train_frames": len(sim), "epochs": epochs, "train_s": train_s,
            "sim_train_ap": train_check.sim_ap, "heldout_sim_ap": check.sim_ap,
            "real_zero_shot_ap": check.real_zero_shot_ap, "heldout_frames": len(held),
            "real_val_frames": len(real_val)}


def _fmt(v, spec=".2f") -> str:
    if isinstance(v, tuple):
        return "/".join(_fmt(x, "+.0f") for x in v)
    return "nan" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, spec)


def main() -> dict:
    n = _sizes()
    out = Path(os.environ.get("SIM2RADAR_BENCH_FIDELITY_OUT", "out/bench_fidelity"))
    store, exp = out / "store", out / "openpcdet"
    held = heldout_seeds(n["worlds"])
    print(f"held-out worlds {held[0]}..{held[-1]} ({len(held)}) x {n['frames']} frames; "
          f"output {out}")
    t0 = time.perf_counter()
    _generate(held, n["frames"], "both", "ti-mmwcas", store, "fidelity-heldout",
              exp / "heldout", seed=n["seed"])
    _generate(held, n["frames"], None, "ti-mmwcas-reference", store, "fidelity-heldout-ref",
              exp / "heldout_ref", reference=True, seed=n["seed"])
    print(f"held-out frames generated in {time.perf_counter() - t0:.0f} s")
    gt_root = exp / "heldout" / "ground_truth"
    domains = {"gt": gt_root, "rec": exp / "heldout" / "reconstructed",
               "ref": exp / "heldout_ref"}
    table = {k: measure_domain(v, gt_root, n["frames"], n["seed"]) for k, v in domains.items()}
    rows = [("points per frame (median)", "points_per_frame", ".0f"),
            ("behind first surface > 1 m", "behind_share", ".1%"),
            ("beyond 0.85 R_max", "beyond_share", ".1%"),
            ("points in a door label box (median)", "points_per_label", ".1f"),
            ("door label boxes empty", "labels_empty", ".0%"),
            ("door label boxes with < 5 points", "labels_under_5", ".0%"),
            ("azimuth covered 1-99 % [deg]", "azimuth_1_99_deg", ""),
            ("labels vs true doors: recall", "label_recall", ".0%"),
            ("labels vs true doors: precision", "label_precision", ".0%"),
            ("matched label width error [m]", "label_width_error_m", ".2f"),
            ("matched label depth error [m]", "label_depth_error_m", ".2f")]
    print("\n| figure | ray-traced, ground truth | ray-traced, reconstructed | reference |")
    print("|---|---|---|---|")
    for label, key, spec in rows:
        print(f"| {label} | " + " | ".join(_fmt(table[d][key], spec) for d in domains) + " |")
    for d in domains:
        print(f"  {d}: {table[d]['frames']} frames, {table[d]['labels']} labels, "
              f"{table[d]['gt_doors']} true doors seen")
    result: dict = {"sizes": n, "heldout_seeds": held, "table": table}
    if n["learn"]:
        t1 = time.perf_counter()
        train = list(range(TRAIN_FIRST_SEED, TRAIN_FIRST_SEED + n["train_worlds"]))
        real_seeds = list(range(REAL_FIRST_SEED, REAL_FIRST_SEED + n["real_worlds"]))
        half = max(1, len(real_seeds) // 2)
        from sim2radar.worlds import world_id_for

        splits = {"train": [world_id_for(s) for s in real_seeds[:half]],
                  "val": [world_id_for(s) for s in real_seeds[half:]], "test": []}
        _generate(train, n["train_frames"], "both", "ti-mmwcas", store, "fidelity-train",
                  exp / "train", seed=n["seed"])
        _generate(real_seeds, n["real_frames"], None, "ti-mmwcas-reference", store,
                  "fidelity-real", exp / "real", splits=splits, reference=True, seed=n["seed"])
        print(f"\ntraining data generated in {time.perf_counter() - t1:.0f} s")
        learn = {g: learnability(out, exp / "train" / g, exp / "heldout" / g, exp / "real", g)
                 for g in ("reconstructed", "ground_truth")}
        print("\npre-training learnability (study profile, "
              f"{STUDY_PRETRAIN_STEPS} steps; 3D AP R40 @ IoU 0.3):")
        print("| sim geometry | train frames | AP on its train frames | AP on held-out sim "
              "worlds | zero-shot AP on proxy-real val |")
        print("|---|---|---|---|---|")
        for g, r in learn.items():
            print(f"| {g} | {r['sim_train_frames']} | {_fmt(r['sim_train_ap'], '.1f')} | "
                  f"{_fmt(r['heldout_sim_ap'], '.1f')} ({r['heldout_frames']} frames) | "
                  f"{_fmt(r['real_zero_shot_ap'], '.1f')} ({r['real_val_frames']} frames) |")
        result["learnability"] = learn
    result["seconds"] = time.perf_counter() - t0
    print(f"\ntotal {result['seconds']:.0f} s")
    return result


if __name__ == "__main__":
    main()
