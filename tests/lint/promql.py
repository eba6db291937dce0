"""The little of PromQL the shipped alert rules use (docs/alerts/waraps-lint.rules.yml),
evaluated exactly over one scrape: promtool is not at hand, and a rule whose expression
does not do what it says must fail a test.

An expression is terms joined by ``or``; a term is ``SELECTOR OP NUMBER`` or
``time() - SELECTOR OP NUMBER``; a selector is a metric name with optional ``{label="value"}``
matchers. ``OP`` is one of ``== != > < >= <=``. As Prometheus does: a comparison keeps the
samples for which it holds (their values unchanged), ``time() - v`` drops the metric name, and
``a or b`` is ``a`` and those samples of ``b`` whose labels (name aside) match none of ``a``.
Anything else is refused: the rules must stay within what this evaluates.
"""

from __future__ import annotations

import operator
import re
from collections.abc import Iterable
from dataclasses import dataclass

OPS = {"==": operator.eq, "!=": operator.ne, ">=": operator.ge, "<=": operator.le,
       ">": operator.gt, "<": operator.lt}
TERM = re.compile(r"^\s*(?P<time>time\(\)\s*-\s*)?(?P<name>[a-zA-Z_:][a-zA-Z0-9_:]*)"
                  r"(?:\{(?P<matchers>[^}]*)\})?\s*(?P<op>==|!=|>=|<=|>|<)\s*"
                  r"(?P<number>-?[0-9]+(?:\.[0-9]+)?)\s*$")
MATCHER = re.compile(r'\s*([a-zA-Z_][a-zA-Z0-9_]*)\s*=\s*"([^"]*)"\s*')


@dataclass(frozen=True)
class Sample:
    name: str
    labels: tuple[tuple[str, str], ...]
    value: float

    def label(self, key: str) -> str:
        return dict(self.labels).get(key, "")


def scrape(families: Iterable[object], *, job: str, up: bool) -> list[Sample]:
    """The samples of a scrape (``prometheus_client.parser`` families), with the ``up``
    series Prometheus adds for the target."""
    found = [Sample(s.name, tuple(sorted(s.labels.items())), float(s.value))
             for f in families for s in f.samples]  # type: ignore[attr-defined]
    return [*found, Sample("up", (("job", job),), 1.0 if up else 0.0)]


def evaluate(expr: str, samples: list[Sample], now: float) -> list[Sample]:
    """The instant vector ``expr`` yields at ``now`` (Unix seconds): an alert fires for each."""
    result: list[Sample] = []
    for text in expr.split(" or "):
        term = _term(text, samples, now)
        seen = {s.labels for s in result}
        result += [s for s in term if s.labels not in seen]
    return result


def _term(text: str, samples: list[Sample], now: float) -> list[Sample]:
    m = TERM.match(text)
    if m is None:
        raise ValueError(f"not in the PromQL this evaluates: {text!r}")
    matchers = dict(MATCHER.findall(m.group("matchers") or ""))
    if (m.group("matchers") or "").strip() and not matchers:
        raise ValueError(f"label matchers not understood: {text!r}")
    picked = [s for s in samples if s.name == m.group("name")
              and all(s.label(k) == v for k, v in matchers.items())]
    if m.group("time"):
        picked = [Sample("", s.labels, now - s.value) for s in picked]
    compare, number = OPS[m.group("op")], float(m.group("number"))
    return [s for s in picked if compare(s.value, number)]
