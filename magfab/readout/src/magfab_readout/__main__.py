"""``python -m magfab_readout``: the same as the ``magfab-readout`` command."""

import sys

from .cli import main

sys.exit(main())
