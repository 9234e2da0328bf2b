"""``python -m ikid`` = the ``ikid`` command."""

import sys

from ikid.cli import main

sys.exit(main())
