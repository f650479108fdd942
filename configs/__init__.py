"""The configurations every command loads by name, shipped with the package as data.

This folder installs as ``sim2radar.configs`` and is read through :mod:`importlib.resources`
(:func:`sim2radar.configio.bundled_config`), so the commands find these files the same way
from a checkout, an editable install or a wheel. Edit a copy and pass its path instead of a
name to use your own."""
