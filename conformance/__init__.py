"""Conformance test suite and protocol validator for the WARA-PS Core System API.

PYTEST_DONT_REWRITE: the package is imported before pytest starts (`waraps-conformance demo`
runs pytest in process); its own modules need no assertion rewriting.
"""

from __future__ import annotations

__version__ = "0.1.0"
__all__ = ["__version__"]
