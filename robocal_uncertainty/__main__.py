"""``python -m robocal_uncertainty`` runs the command line."""

import sys

from robocal_uncertainty.cli import main

sys.exit(main())
