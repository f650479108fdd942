"""Errors that name a sweep's settings without knowing how a caller spells them.

The library does not know the command line: a message such as "the sweep name 'x' is not one
folder name under the sweeps folder" names the *setting* (``name``, ``out``, the ``sim-gt``
dataset), and the caller that took it from its own option says it that way. A
:class:`SettingError`'s message is a template with ``{setting}`` fields; ``str(error)`` fills
them with :data:`SETTING_NAMES` (the library's words), :meth:`SettingError.spelled` with the
caller's (``sim2radar sweep`` passes its flags: ``--name``, ``--out``, ``--sim-gt``).

    raise SettingError("{name} {value}: use letters, digits ...", value=repr(name))
    str(err)                              # "the sweep name 'a/b': use letters, digits ..."
    err.spelled({"name": "--name"})       # "--name 'a/b': use letters, digits ..."
"""

from __future__ import annotations

import re
from collections.abc import Callable, Mapping

__all__ = ["SETTING_NAMES", "SettingError", "dataset_setting"]

#: the library's words for the settings a :class:`SettingError` names
SETTING_NAMES: dict[str, str] = {
    "name": "the sweep name",
    "out": "the sweeps folder",
    "preregistration": "the profile's preregistration path",
    "force": "the runs to redo",
    "runs_per_gpu": "runs per GPU",
    "workers": "the number of concurrent runs",
    "mlflow_experiment": "another MLflow experiment name",
    "root": "the sweeps folder",
}
#: a ``{setting}`` field of a template (``{name}``, ``{dataset:sim-gt}``, ``{value}``)
_FIELD = re.compile(r"\{([A-Za-z_][A-Za-z0-9_]*(?::[A-Za-z0-9_.-]+)?)\}")


def dataset_setting(role: str) -> str:
    """The setting naming a dataset role's source: ``dataset:<role>``."""
    return f"dataset:{role}"


class SettingError(ValueError):
    """A wrong sweep setting, its message naming settings as ``{setting}`` fields.

    Parameters
    ----------
    template : str — the message; ``{setting}`` (a key of :data:`SETTING_NAMES`, or
        ``{dataset:ROLE}``: the ROLE dataset) and ``{field}`` for each of ``values``.
    values : str — text filled in as it is (user input, counts); never read as a template.
    """

    def __init__(self, template: str, **values: str) -> None:
        self.template, self.values = template, dict(values)
        super().__init__(self.spelled())

    @property
    def settings(self) -> list[str]:
        """The settings the message names, in order (``name``, ``dataset:sim-gt``)."""
        return [f for f in dict.fromkeys(_FIELD.findall(self.template)) if f not in self.values]

    def spelled(self, names: Mapping[str, str] | Callable[[str], str | None] | None = None
                ) -> str:
        """The message with each setting spelled by ``names`` (setting -> word, e.g. a
        command's flag; a mapping or a function returning None for "the library's word"),
        the others by :data:`SETTING_NAMES` (a dataset as "the ROLE dataset")."""
        lookup = names.get if isinstance(names, Mapping) else (names or (lambda _s: None))

        def fill(m: re.Match) -> str:
            key = m[1]
            if key in self.values:
                return str(self.values[key])
            given = lookup(key)
            if given is not None:
                return given
            if key.startswith("dataset:"):
                return f"the {key.partition(':')[2]} dataset"
            return SETTING_NAMES.get(key, key)

        return _FIELD.sub(fill, self.template)

    def __reduce__(self):       # picklable (a Dask worker's error travels back)
        return (_rebuild, (type(self), self.template, self.values))


def _rebuild(cls: type[SettingError], template: str, values: dict[str, str]) -> SettingError:
    err = cls.__new__(cls)
    SettingError.__init__(err, template, **values)
    return err
