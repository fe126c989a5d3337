"""``python -m manip_id`` runs the ``manip-id`` command."""

import sys

from .cli import main

sys.exit(main())
