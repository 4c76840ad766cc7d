"""``python -m aquarom_fenics.cli``: the ``aquarom`` command."""
import sys

from aquarom_fenics.cli import main

sys.exit(main())
