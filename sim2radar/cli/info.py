"""``sim2radar info``: versions and the hardware the factory will use."""

from __future__ import annotations

from sim2radar.cli._app import app


@app.command()
def info() -> None:
    """Print package versions, the Mitsuba variant and the torch device that will be used."""
    import importlib.metadata as md

    from sim2radar.hardware import mitsuba_variant, torch_device

    for pkg in ("sim2radar", "mitsuba", "drjit", "torch", "prefect", "pyarrow", "numpy"):
        try:
            print(f"{pkg:10s} {md.version(pkg)}")
        except md.PackageNotFoundError:
            print(f"{pkg:10s} (not installed)")
    print(f"{'mitsuba':10s} variant: {mitsuba_variant()}")
    print(f"{'torch':10s} device: {torch_device()}")
