"""``python -m ikid`` = the ``ikid`` command."""

import sys

from ikid.cli import main

if __name__ == "__main__":  # not when a spawned worker process imports this module
    sys.exit(main())
