"""``python -m mudoe``: the command line (see :mod:`mudoe.cli`)."""
import sys

from .cli import main

sys.exit(main())
