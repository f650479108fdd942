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


@app.command()
def presets() -> None:
    """List the built-in radar presets with their derived figures (range/angle resolution, ...)."""
    from sim2radar.radar import load_radar_config, preset_names

    for name in preset_names():
        derived = load_radar_config(name).derived()
        print(
            f"{name:12s} range res {derived['range_resolution_m'] * 100:.2f} cm, "
            f"max range {derived['max_range_m']:.1f} m, "
            f"az res {derived['azimuth_resolution_deg']:.2f} deg, "
            f"el res {derived['elevation_resolution_deg']:.1f} deg, "
            f"{derived['n_azimuth_virtual']} az virtual elements, "
            f"cube {derived['cube_shape']}, {derived['n_rays']} rays/frame"
        )
