"""Which rules the validator examined on a message, asked once per message shape.

``Validator.examined`` costs an evaluation of the message's schema, 10-100 times validating it
(bench/bench_validate.py). The Monitor asks here for every message; the answer is kept by
shape on the message's route (the Monitor's per-topic ``_Route``: ``content_fields``,
``shapes``, ``decided_by``, ``last_decided``) and, for a fleet whose units send the same
shapes, shared across topics of a kind.
"""

from __future__ import annotations

from typing import Any

import orjson

from conformance.validator import Examined, Validation, Validator, read_in_part

MAX_SHAPES = 64
"""Message shapes whose examined rules are kept per topic (more are asked for each message)."""

MAX_SHARED_SHAPES = 4096
"""Message shapes whose examined rules are kept for every topic of their kind."""

MAX_FROZEN_BYTES = 1024
"""Deciding values that are lists or objects longer than this as JSON are not kept as keys."""

MAX_SHAPE_KEYS = 64
"""Top-level keys of a message beyond which its shape is not worked out (asked each time)."""


class Shapes:
    """The examined sets of one Monitor's messages, by shape."""

    def __init__(self, validator: Validator) -> None:
        self.validator = validator
        self.shared: dict[tuple[Any, ...], Examined] = {}
        """Examined sets by topic kind, shape and deciding values, for every topic."""
        self.deciders: dict[tuple[Any, ...], tuple[str, ...]] = {}
        """Topic kind and shape -> the fields learnt to decide a branch for that shape."""

    def examined(self, route: Any, v: Validation) -> Examined:
        """``Validator.examined(v)``, asked once per message shape of a topic: the kind, the
        top-level keys, which of their values are empty, the types of the content fields (of a
        message that broke a rule),
        and the values of the fields that decided a branch (``Examined.decided_by``, learnt
        from the answers: a field newly seen deciding clears what was kept). Nested optional
        parts are taken to be as in the first message of a shape. Without this cache the
        full lint runs at a fraction of its speed (bench/bench_lint.py: evaluation costs
        10-100x validation, bench/bench_validate.py)."""
        m = v.message
        m_type = m.__class__
        if v.topic.kind is not route.topic_kind or v.violations and read_in_part(v):
            return self.validator.examined(v)  # a validator of its own mind, or a part: ask
        if m_type is dict:
            if len(m) > MAX_SHAPE_KEYS:
                return self.validator.examined(v)
            # Which values are empty: True when none is (the usual case, one C loop). The
            # content fields' types only where the message broke a rule: in a valid one they
            # are those its content rules examine (test_examined_coverage.py).
            fields = route.content_fields
            key: tuple[Any, ...] = (v.kind, tuple(m),
                                    all(m.values()) or tuple(map(bool, m.values())),
                                    tuple(map(type, map(m.get, fields)))
                                    if fields and v.violations else ())
        elif m_type is float or m_type is int or m_type is str or m_type is bool:
            key = (v.kind, m_type)
        else:  # not decoded (few rules, no schema), or an array (its items decide)
            return self.validator.examined(v)
        decided_by = route.decided_by
        if decided_by:
            if m_type is not dict or "" in decided_by:
                return self.validator.examined(v)  # the message's own value decides
            values = tuple(map(m.get, decided_by))
            last = route.last_decided
            if last is not None and last[0] == key and last[1] == values:
                return last[2]  # a steady stream (lists and objects compared, not hashed)
            frozen = _hashable(values)  # values that alternate (response, command): a dict
            if frozen is not None:
                found = route.shapes.get((key, frozen))
                if found is not None:
                    route.last_decided = (key, values, found)
                    return found
        else:
            found = route.shapes.get(key)
            if found is not None:
                return found
        return self._learn(route, v, key, decided_by)

    def _learn(self, route: Any, v: Validation, key: tuple[Any, ...],
               decided_by: tuple[str, ...]) -> Examined:
        """A shape the topic has not cached: another topic's answer (a fleet sends the same
        shapes), else the validator's; kept for the topic and across topics, and the fields
        newly seen deciding a branch learnt (what the topic kept is cleared then)."""
        m = v.message
        m_type = m.__class__
        # Units of one fleet send the same shapes: another topic's answer serves. Its key
        # says all that decides: the topic kind, whether it names a unit, the shape, and the
        # values of the fields learnt (on any topic) to decide a branch for that shape.
        base = (route.topic_kind, v.topic.unit is None, key)
        need = self.deciders.get(base, ())
        if m_type is dict and not set(decided_by) <= set(need):
            need = tuple(sorted({*need, *decided_by}))
        frozen = _hashable(tuple(map(m.get, need))) if need and m_type is dict else ()
        examined = self.shared.get((base, need, frozen)) if frozen is not None else None
        if examined is None or not set(examined.decided_by) <= set(need):
            examined = self.validator.examined(v)
            if not set(examined.decided_by) <= set(need):
                need = tuple(sorted({*need, *examined.decided_by}))
                # The message's own value ("") decides: not kept (asked each time).
                frozen = (_hashable(tuple(map(m.get, need))) if m_type is dict
                          and "" not in need else None)
            if len(self.shared) < MAX_SHARED_SHAPES and frozen is not None:
                self.deciders[base] = need
                self.shared[(base, need, frozen)] = examined
        if not set(examined.decided_by) <= set(decided_by):
            decided_by = route.decided_by = tuple(sorted({*decided_by, *examined.decided_by}))
            route.shapes.clear()
        if decided_by:
            if m_type is dict:
                values = tuple(map(m.get, decided_by))
                route.last_decided = (key, values, examined)
                frozen = _hashable(values)
                if frozen is not None and len(route.shapes) < MAX_SHAPES:
                    route.shapes[(key, frozen)] = examined
        elif len(route.shapes) < MAX_SHAPES:
            route.shapes[key] = examined
        return examined


_SCALAR_TYPES = (str, int, float, bool, type(None))


def _hashable(values: tuple[Any, ...]) -> Any:
    """``values`` as a dict key: themselves when JSON scalars (the usual case), else their
    canonical JSON text (a start-task's ``task`` object), or None when that is too long to
    keep (such a message is evaluated each time: exact, only slower)."""
    if all(type(x) in _SCALAR_TYPES for x in values):
        return values
    text = orjson.dumps(values, option=orjson.OPT_SORT_KEYS)
    return text if len(text) <= MAX_FROZEN_BYTES else None
