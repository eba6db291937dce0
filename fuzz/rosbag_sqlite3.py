"""Fuzz target: the bytes of a ROS 2 bag's sqlite3 storage (its ``.db3`` file, with the good bag's ``metadata.yaml``),
read by ``BagReader`` as ``lint --from`` does. Seeded with a conformant bag (``fuzz.seeds``).

Invariant (``fuzz.bags``): read whole, or refused with a one-line ``BagError``; a message that
cannot be deserialized refuses the bag (no verdict on a damaged container); time proportional
to the input.
"""

from __future__ import annotations

from fuzz.bags import target

prepare, test_one_input = target("sqlite3")
