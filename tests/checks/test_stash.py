"""A unit's typed components (``checks/stash.py``): keys by identity, made once, copied apart."""

from __future__ import annotations

import copy

from conformance.checks.base import UnitState
from conformance.checks.conversation import CONVERSATIONS, Conversations, conversations
from conformance.checks.stash import Stash, StashKey
from conformance.topics import UnitAddress

COUNTER: StashKey[list[int]] = StashKey("counter")


def test_a_component_is_made_once_and_found_by_its_key() -> None:
    stash = Stash()
    made: list[list[int]] = []

    def make() -> list[int]:
        made.append([])
        return made[-1]

    first = stash.setdefault(COUNTER, make)
    first.append(1)
    assert stash.setdefault(COUNTER, make) is first
    assert len(made) == 1
    assert stash[COUNTER] == [1] and stash.get(COUNTER) == [1] and COUNTER in stash


def test_keys_compare_by_identity_not_by_name() -> None:
    stash = Stash()
    twin: StashKey[list[int]] = StashKey("counter")
    stash[COUNTER] = [1]
    assert twin not in stash
    assert stash.get(twin) is None
    assert stash.get(twin, [2]) == [2]


def test_a_falsy_component_is_kept_not_made_again() -> None:
    stash = Stash()
    flag: StashKey[bool] = StashKey("flag")
    stash[flag] = False
    assert stash.setdefault(flag, lambda: True) is False


def test_with_item_copies_the_stash_and_leaves_the_original_alone() -> None:
    stash = Stash()
    stash[COUNTER] = [1]
    other: StashKey[str] = StashKey("other")
    stash[other] = "kept"
    copied = stash.with_item(COUNTER, [2])
    assert copied[COUNTER] == [2] and copied[other] == "kept"
    assert stash[COUNTER] == [1]
    del copied[other]
    assert other in stash and other not in copied


def test_a_unit_keeps_its_conversations_under_their_key() -> None:
    unit = UnitState(UnitAddress("waraps", "air", "simulation", "dji0"), agent_uuid="life-1")
    assert CONVERSATIONS not in unit.stash
    c = conversations(unit)
    assert isinstance(c, Conversations) and unit.stash[CONVERSATIONS] is c
    assert c.life == "life-1" and c.lives == ["life-1"]
    assert conversations(unit) is c
    deep = copy.deepcopy(unit.stash)  # a finish check judges on a copy (judged_on_a_copy)
    assert deep[CONVERSATIONS] is not c and deep[CONVERSATIONS].life == "life-1"
