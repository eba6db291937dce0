"""A unit's typed components: what each check keeps of a unit between messages.

In the spirit of pytest's ``Stash``: a component's key is a ``StashKey[T]`` object defined next
to the component's owner (``CONVERSATIONS`` beside ``Conversations``, which hold the unit's
``protocol.Model``), so the checks that read it import it by name and the type checker knows
what they get; no string names a component. Each check declares the components it
reads (``@check(..., reads=(CONVERSATIONS,))``; ``tests/plugin/test_declared_reads.py``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Generic, TypeVar, cast, overload

T = TypeVar("T")
D = TypeVar("D")


class StashKey(Generic[T]):
    """The key of one kind of component; compared by identity. ``name`` is only for people."""

    __slots__ = ("name",)

    def __init__(self, name: str) -> None:
        self.name = name

    def __repr__(self) -> str:
        return f"StashKey({self.name!r})"

    def __copy__(self) -> StashKey[T]:
        return self  # a key is an identity: a copied stash is found by the same keys

    def __deepcopy__(self, memo: dict[int, Any]) -> StashKey[T]:
        return self


class Stash:
    """A unit's components, each under its ``StashKey[T]``, typed ``T``.

    ``get`` is a dict lookup and no more: rate trackers read it on every periodic message.
    """

    __slots__ = ("_items",)

    def __init__(self, items: dict[StashKey[Any], Any] | None = None) -> None:
        self._items: dict[StashKey[Any], Any] = dict(items) if items else {}

    def __getitem__(self, key: StashKey[T]) -> T:
        return cast(T, self._items[key])

    def __setitem__(self, key: StashKey[T], value: T) -> None:
        self._items[key] = value

    def __delitem__(self, key: StashKey[T]) -> None:
        del self._items[key]

    def __contains__(self, key: StashKey[Any]) -> bool:
        return key in self._items

    def __len__(self) -> int:
        return len(self._items)

    @overload
    def get(self, key: StashKey[T]) -> T | None: ...

    @overload
    def get(self, key: StashKey[T], default: D) -> T | D: ...

    def get(self, key: StashKey[Any], default: Any = None) -> Any:
        return self._items.get(key, default)

    def setdefault(self, key: StashKey[T], factory: Callable[[], T]) -> T:
        """The component under ``key``, made by ``factory()`` on first use."""
        items = self._items
        value = items.get(key)
        if value is None and key not in items:
            value = items[key] = factory()
        return cast(T, value)

    def with_item(self, key: StashKey[T], value: T) -> Stash:
        """A shallow copy holding ``value`` under ``key`` (a finish check's copy of a unit)."""
        copy = Stash(self._items)
        copy[key] = value
        return copy

    def __repr__(self) -> str:
        return f"Stash({', '.join(k.name for k in self._items)})"
