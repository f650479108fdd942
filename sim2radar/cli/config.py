"""``sim2radar config``: the configs bundled with the package — list them, print one, copy one
to start your own from (relative paths to other bundled files made absolute, so the copy works
anywhere)."""

from __future__ import annotations

import re
from pathlib import Path

import typer

from sim2radar.cli._app import app

__all__ = ["config_app", "find_bundled"]

config_app = typer.Typer(rich_markup_mode=None, no_args_is_help=True,
                         help="The configs bundled with sim2radar: list, show, copy.")
app.add_typer(config_app, name="config")

_RELATIVE = re.compile(r"^(\s*[A-Za-z_][\w-]*:\s*)(\.\.?/[^\s#]+)")


def _bundled() -> dict[str, Path]:
    """``kind/name`` -> file of every bundled config (radar presets as ``radar/<name>``)."""
    from sim2radar.configio import CONFIG_KINDS, _bundled_dir, bundled_configs
    from sim2radar.radar.config import PRESET_DIR, preset_names

    out = {f"{kind}/{name}": _bundled_dir(kind) / f"{name}.yaml"
           for kind in CONFIG_KINDS for name in bundled_configs(kind)}
    out.update({f"radar/{name}": PRESET_DIR / f"{name}.yaml" for name in preset_names()})
    return out


def find_bundled(name: str) -> tuple[str, Path]:
    """The bundled config ``kind/name`` (or a bare ``name`` that only one kind has)."""
    every = _bundled()
    if name in every:
        return name, every[name]
    matches = [k for k in every if k.split("/", 1)[1] == name]
    if len(matches) == 1:
        return matches[0], every[matches[0]]
    hint = f"it is {matches}: give kind/name" if matches else "`sim2radar config list` lists them"
    typer.secho(f"error: no bundled config {name!r}; {hint}", fg="red", err=True)
    raise typer.Exit(2)


@config_app.command("list")
def list_cmd() -> None:
    """Every bundled config, as kind/name."""
    for key, path in sorted(_bundled().items()):
        first = next((ln.lstrip("# ").strip() for ln in path.read_text().splitlines()
                      if ln.startswith("#") and ln.strip("# ")), "")
        typer.echo(f"{key:45s} {first[:80]}")


@config_app.command("show")
def show_cmd(name: str = typer.Argument(..., help="kind/name, e.g. experiment/demo.")) -> None:
    """Print a bundled config."""
    _, path = find_bundled(name)
    typer.echo(path.read_text(), nl=False)


@config_app.command("copy")
def copy_cmd(name: str = typer.Argument(..., help="kind/name, e.g. experiment/demo."),
             dest: Path = typer.Argument(..., help="The file (or folder) to write."),
             force: bool = typer.Option(False, help="Overwrite an existing file.")) -> None:
    """Copy a bundled config to start your own from; its relative paths to other bundled files
    (an experiment profile's detector) become absolute, so the copy works from anywhere."""
    key, path = find_bundled(name)
    if dest.is_dir():
        dest = dest / path.name
    if dest.exists() and not force:
        typer.secho(f"error: {dest} exists; choose another name or pass --force", fg="red",
                    err=True)
        raise typer.Exit(2)

    def absolute(m: re.Match) -> str:
        target = (path.parent / m.group(2)).resolve()
        return f"{m.group(1)}{target}" if target.exists() else m.group(0)

    text = "\n".join(_RELATIVE.sub(absolute, ln) for ln in path.read_text().splitlines())
    dest.parent.mkdir(parents=True, exist_ok=True)
    dest.write_text(f"# copied from sim2radar's bundled {key}\n{text}\n")
    typer.echo(f"wrote {dest} (from {key})")
