"""``sim2radar sweep``'s dataset options: one per dataset role of the condition registry, mapped
to their roles through it (the sweep itself is tested in tests/flows/test_experiment.py)."""

from __future__ import annotations

import pytest
import typer

from sim2radar.cli import app
from sim2radar.cli.experiment import sweep_datasets
from sim2radar.experiment.profiles import CONDITIONS


def test_every_conditions_dataset_has_its_option():
    sweep = typer.main.get_command(app).commands["sweep"]
    options = {o for p in sweep.params for o in getattr(p, "opts", ())}
    flags = {c.flag for c in CONDITIONS.values() if c.flag}
    assert "--sim" in flags                                    # SIM, the first argument
    assert flags - {"--sim"} <= options
    given = {f: f"data/{f[2:]}" for f in flags - {"--sim"}}
    assert sweep_datasets("data/s", "data/r", {**given, "--sim-gt": None}) == {
        "sim": "data/s", "real": "data/r",
        **{CONDITIONS[n].sim_role: f"data/{CONDITIONS[n].sim_role}" for n in CONDITIONS
           if CONDITIONS[n].flag not in (None, "--sim", "--sim-gt")}}
    with pytest.raises(ValueError, match="--sim-noisy"):
        sweep_datasets("s", "r", {"--sim-noisy": "n"})
