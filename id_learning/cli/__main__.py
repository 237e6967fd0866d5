"""``python -m id_learning.cli``."""

from __future__ import annotations

import sys

from id_learning.entry import cli

sys.exit(cli())
