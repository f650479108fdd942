"""The experiment sweep's science (paper §6): pre-train the PointPillars encoder on simulated
radar, fine-tune on real radar, and compare 3D AP with training from scratch over real-data
fractions x paired trials.

- :mod:`~sim2radar.experiment.profiles` — :class:`ExperimentProfile` (``paper``, ``study``,
  ``demo``, ``smoke``, bundled as ``sim2radar.configs``) and the registry of conditions.
- :mod:`~sim2radar.experiment.subsets` — trial seeds and nested real-data subsets.
- :mod:`~sim2radar.experiment.plan` — the typed :class:`SweepPlan`: the runs of a sweep and
  what identifies each.
- a sweep's phases, one module each: :mod:`~sim2radar.experiment.prepare` (datasets by role,
  the settings check, the plan), :mod:`~sim2radar.experiment.cost` (what it would cost:
  ``sweep --plan``) and :mod:`~sim2radar.experiment.finish` (statistics, report, dashboard);
  ``tasks/experiment.py`` executes one pre-training or fine-tuning, ``tasks/sweep.py`` the
  whole sweep (the ``sweep`` job's driver).
- :mod:`~sim2radar.experiment.stats` — paired statistics (t-interval, Holm, d_z, bootstrap).
- :mod:`~sim2radar.experiment.report` — Table 1 as Markdown and as artifact rows.
- :mod:`~sim2radar.experiment.data`, :mod:`~sim2radar.experiment.runner` — datasets of a sweep
  and one training run (import them directly; they load torch).
- :mod:`~sim2radar.experiment.tracking` — a sweep folder mirrored into MLflow (import it
  directly; MLflow is the optional ``mlflow`` extra).

``tasks/experiment.py`` executes a sweep's runs (keys, store, claims), ``tasks/sweep.py`` drives
the sweep on a runner, and ``flows/run_experiment.py`` runs that driver with Prefect; nothing
here, nor in ``tasks/``, imports Prefect.

The names below are imported on first use (PEP 562): importing one module of the package (the
store's schemas import :mod:`~sim2radar.experiment.rows`) does not load the statistics' SciPy.
"""

import importlib
from typing import Any

#: public name -> the module that defines it
_EXPORTS = {
    **dict.fromkeys(("PretrainSpec", "RunSpec", "epochs_for", "plan_sweep",
                     "pretrain_key_inputs", "run_key_inputs"), "plan"),
    **dict.fromkeys(("ABLATIONS", "CONDITIONS", "Condition", "ExperimentProfile",
                     "load_profile"), "profiles"),
    **dict.fromkeys(("results_markdown", "results_table_rows"), "report"),
    **dict.fromkeys(("DEFAULT_METRIC", "holm_adjust", "sweep_stats"), "stats"),
    **dict.fromkeys(("n_real_frames", "real_subset", "trial_seed"), "subsets"),
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name not in _EXPORTS:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_EXPORTS})
