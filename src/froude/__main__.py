"""``python -m froude``: the command line (froude.apps.cli)."""
import sys

from .apps.cli import main

sys.exit(main())
