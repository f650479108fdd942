"""Named backends for learned / swappable stages (Sionna RT's registry habit).

A stage declares one :class:`Registry`; each backend registers under a name; the config
picks the name. An unknown name fails with the list of known ones::

    DEPTH_BACKENDS = Registry("depth")

    @DEPTH_BACKENDS.register("lidar")
    class LidarDepth: ...

    backend_cls = DEPTH_BACKENDS.get(config.depth.backend)
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Generic, TypeVar

T = TypeVar("T")

__all__ = ["Registry", "UnknownBackendError"]


class UnknownBackendError(KeyError):
    """Raised for a backend name that is not registered; the message lists known names."""

    def __str__(self) -> str:  # KeyError quotes its message; keep it readable
        return str(self.args[0])


class Registry(Generic[T]):
    """A name -> object map for one stage's backends."""

    def __init__(self, stage: str) -> None:
        self.stage = stage
        self._items: dict[str, T] = {}

    def register(self, name: str) -> Callable[[T], T]:
        """Decorator: register the decorated class or function under ``name``."""

        def deco(obj: T) -> T:
            if name in self._items and self._items[name] is not obj:
                raise ValueError(f"{self.stage} backend {name!r} is already registered")
            self._items[name] = obj
            return obj

        return deco

    def get(self, name: str) -> T:
        """Return the backend registered as ``name``."""
        try:
            return self._items[name]
        except KeyError:
            known = ", ".join(sorted(self._items)) or "(none)"
            raise UnknownBackendError(
                f"unknown {self.stage} backend {name!r}; known backends: {known}"
            ) from None

    def names(self) -> list[str]:
        """Registered names, sorted."""
        return sorted(self._items)

    def __contains__(self, name: object) -> bool:
        return name in self._items

    def __iter__(self) -> Iterator[str]:
        return iter(self.names())
