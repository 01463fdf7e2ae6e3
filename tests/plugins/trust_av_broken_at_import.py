"""A plug-in module that exits at import (``SystemExit(0)``, as a stray ``sys.exit()`` at
module level does); registered by ``tests/support/broken_plugins.py`` as predictor
``broken_at_import``."""

raise SystemExit(0)
