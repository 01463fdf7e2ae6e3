"""``python -m trust_av.cli``: the same as ``trust-av``."""

from __future__ import annotations

import sys

from trust_av.cli.main import main

__all__: list[str] = []

sys.exit(main())
