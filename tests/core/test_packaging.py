"""What a non-editable install ships: every package of conformance/ is listed in pyproject.toml
(an unlisted one is left out of the wheel: `pip install .` then fails on import)."""

from __future__ import annotations

import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def test_every_package_of_conformance_is_listed_in_pyproject() -> None:
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())
                 ["tool"]["setuptools"]["packages"])
    on_disk = {".".join(p.parent.relative_to(ROOT).parts)
               for p in (ROOT / "conformance").rglob("__init__.py")}
    missing = sorted(on_disk - listed)
    assert not missing, (f"packages not listed in pyproject.toml [tool.setuptools] packages "
                         f"(left out of the wheel): {missing}")
