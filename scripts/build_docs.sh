#!/usr/bin/env bash
# Build the documentation site as the test command does: `mkdocs build --strict`, every
# warning fatal (a dead link or anchor, a page missing from the nav, a generated table that
# cannot be built), MkDocs' INFO lines left out of the output. Arguments go to mkdocs
# (`bash scripts/build_docs.sh --site-dir /tmp/site`).
#
# Not `--quiet`: it sets the mkdocs logger to ERROR, so the warnings that --strict counts are
# never emitted and a build with a dead anchor exits 0 (MkDocs 1.6, mkdocs/__main__.py: the
# quiet option's callback sets the level; --strict counts WARNING records through a handler
# on the same logger). tests/graph/test_docs.py plants a dead anchor and builds it both ways.
set -euo pipefail
NO_MKDOCS_2_WARNING=1 mkdocs build --strict "$@" 2>&1 | { grep -v '^INFO ' || true; }
