"""Named registries: one place that lists the choices of a kind (layout methods, assignment
costs, avoidance modes), so schemas, the CLI, the API and the UI read the names from it
instead of copying them.

An unknown name is an error that lists the known ones (as Nav2's collision monitor refuses
an unknown action type). A registry can also be used as a pydantic field type
(:meth:`Registry.as_field`): the value is checked against the registry when it is validated,
and the JSON schema lists the names registered when the schema is made.

>>> colours = Registry("colour", "paint.colour")
>>> _ = colours.add("red", "#f00", "warm")
>>> colours.get("red")
'#f00'
>>> colours.get("blue")
Traceback (most recent call last):
...
swarmpark.core.registry.UnknownNameError: paint.colour: unknown colour 'blue' (known: red)
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, Generic, TypeVar

__all__ = ["Registry", "Entry", "UnknownNameError"]

T = TypeVar("T")


class UnknownNameError(ValueError):
    """A name that is not registered. The message names the field, the value and the known
    names; ``known`` holds them."""

    def __init__(self, message: str, known: tuple[str, ...]):
        super().__init__(message)
        self.known = known


@dataclass(frozen=True)
class Entry(Generic[T]):
    """One registered choice: its name, what it is (a class, a function, a marker) and a
    one-line description for the operator."""

    name: str
    item: T
    description: str


class Registry(Generic[T]):
    """Names of one kind in registration order.

    Parameters
    ----------
    kind
        What a name stands for, for messages (``"layout method"``).
    field
        The user-facing field that takes the name (``"park.method"``), for messages.
    """

    def __init__(self, kind: str, field: str):
        self.kind = kind
        self.field = field
        self._entries: dict[str, Entry[T]] = {}

    def add(self, name: str, item: T, description: str) -> T:
        """Register ``item`` under ``name``; a name can be registered once."""
        if not isinstance(name, str) or not name:
            raise ValueError(f"{self.kind}: a name must be a non-empty string (got {name!r})")
        if name in self._entries:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        if not description:
            raise ValueError(f"{self.kind} {name!r}: needs a description")
        self._entries[name] = Entry(name, item, description)
        return item

    def register(self, name: str, description: str):
        """Decorator form of :meth:`add`."""

        def deco(item: T) -> T:
            return self.add(name, item, description)

        return deco

    def remove(self, name: str) -> T:
        """Unregister ``name`` (a plugin unloaded, a test cleaning up); returns its item."""
        return self._entries.pop(self.check(name)).item

    def names(self) -> tuple[str, ...]:
        return tuple(self._entries)

    def entries(self) -> tuple[Entry[T], ...]:
        return tuple(self._entries.values())

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def error(self, name: object) -> UnknownNameError:
        """The error for an unknown ``name`` (raised by :meth:`get` and :meth:`check`)."""
        known = self.names()
        return UnknownNameError(
            f"{self.field}: unknown {self.kind} {name!r} (known: {', '.join(known)})", known
        )

    def check(self, name: Any) -> str:
        """``name`` if it is registered, else :class:`UnknownNameError`."""
        if not isinstance(name, str) or name not in self._entries:
            raise self.error(name)
        return name

    def get(self, name: Any) -> T:
        """The item registered as ``name``; :class:`UnknownNameError` if there is none."""
        return self._entries[self.check(name)].item

    def describe(self, name: str) -> str:
        return self._entries[self.check(name)].description

    def as_field(self) -> Any:
        """pydantic metadata checking a ``str`` against this registry:
        ``method: Annotated[str, LAYOUT_METHODS.as_field()]``.

        Validation asks the registry at validation time (names registered later count);
        the JSON schema is a string ``enum`` of the names registered when it is made.
        """
        return _RegistryCheck(self)


class _RegistryCheck:
    """pydantic metadata: validate a string against a registry, list its names in the schema."""

    def __init__(self, registry: Registry):
        self.registry = registry

    def _check(self, value: str) -> str:
        if value not in self.registry:
            known = self.registry.names()
            # pydantic prefixes the field path; the message lists the known names.
            raise ValueError(f"unknown {self.registry.kind} (known: {', '.join(known)})")
        return value

    def __get_pydantic_core_schema__(self, source: Any, handler: Any) -> Any:
        from pydantic_core import core_schema

        return core_schema.no_info_after_validator_function(self._check, handler(source))

    def __get_pydantic_json_schema__(self, schema: Any, handler: Any) -> dict:
        out = handler(schema)
        out["enum"] = list(self.registry.names())
        return out
