"""``python -m conformance.cli COMMAND ...``: the console script without its entry point."""

import sys

from conformance.cli import main

sys.exit(main())
