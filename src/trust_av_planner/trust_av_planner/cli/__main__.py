"""``python -m trust_av_planner.cli``: the same as ``trust-av``."""

from __future__ import annotations

import sys

from trust_av_planner.cli.main import main

sys.exit(main())
