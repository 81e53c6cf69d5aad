"""``python -m kinecal`` runs the command-line interface."""

import sys

from kinecal.cli import main

sys.exit(main())
