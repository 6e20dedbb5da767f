"""Named registries: the one list of control laws, variants and fault kinds.

Every list of allowed names (case validation, node parameters, the runner, the docs)
is read from a registry, so adding a law or a fault kind is one module and one
registry entry. Tests register their own entries and remove them afterwards.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Generic, TypeVar

from fahv.errors import ConfigError

T = TypeVar("T")


class Registry(Generic[T]):
    """Name -> entry, in registration order.

    Parameters
    ----------
    what : str
        What the entries are ("control law", "fault kind"), used in messages.
    """

    def __init__(self, what: str) -> None:
        self.what = what
        self._entries: dict[str, T] = {}

    def register(self, name: str, entry: T, replace: bool = False) -> T:
        """Add `entry` under `name` and return it.

        Raises
        ------
        ConfigError
            If the name is taken (unless `replace`) or not an identifier.
        """
        if not name.isidentifier():
            raise ConfigError(f"{self.what} name must be an identifier, got {name!r}")
        if name in self._entries and not replace:
            raise ConfigError(f"{self.what} '{name}' is registered already")
        self._entries[name] = entry
        return entry

    def unregister(self, name: str) -> None:
        """Remove an entry (no error if absent)."""
        self._entries.pop(name, None)

    def __getitem__(self, name: str) -> T:
        """The entry of `name`.

        Raises
        ------
        ConfigError
            Naming the unknown name and the registered ones.
        """
        try:
            return self._entries[name]
        except KeyError:
            raise ConfigError(
                f"unknown {self.what} {name!r}; registered: {', '.join(self._entries)}"
            ) from None

    def get(self, name: str, default: T | None = None) -> T | None:
        """The entry of `name`, or `default` when it is not registered."""
        return self._entries.get(name, default)

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(list(self._entries))

    def names(self) -> tuple[str, ...]:
        """Registered names in registration order."""
        return tuple(self._entries)

    def items(self) -> list[tuple[str, T]]:
        """(name, entry) pairs in registration order."""
        return list(self._entries.items())
