"""``python -m trust_av.cli``: the same as ``trust-av``."""

from __future__ import annotations

import sys

from trust_av.cli.main import main

sys.exit(main())
