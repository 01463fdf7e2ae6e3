#!/usr/bin/env bash
# The project's test command (README): set up .venv if needed, then lint (ruff), type-check
# every module (mypy --strict), build the documentation site in strict mode (mkdocs: a
# broken link or anchor, or a generated table that cannot be built, fails), and run the whole
# test suite (pytest) on six workers for two cores (pytest-xdist, --dist loadgroup, the
# queue in the suite's own order, --no-loadscope-reorder: tests/conftest.py keeps the tests
# that share a module's fixture on one worker, runs the wall-clock tests, which mostly wait,
# on the even-numbered workers and every other test on the odd ones, each lane its longest
# units first by tests/durations.json, so that the waiting tests wait side by side while
# the rest keep both cores busy), and shows the 15 slowest tests of every run
# (--durations). Extra arguments go to pytest, e.g. `bash scripts/test.sh -k nmpc`, or
# `bash scripts/test.sh -n 0` for one process.
#
# `bash scripts/test.sh --fast`: the fast lane, only `pytest tests/core -m "not slow"` (the
# pure tier without its long tests) on two workers, under a minute on two cores; extra
# arguments go to pytest as above.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
source scripts/bootstrap.sh

# The suite's processes keep the byte code they compile (in the project's own .venv and in
# the ignored __pycache__ folders of src/ and tests/), also where PYTHONDONTWRITEBYTECODE is
# set: there pytest rewrote and compiled every test module again in every worker and every
# pytest a test starts (about 2.5 CPU-s each), and every process compiled again what pip had
# left uncompiled (hypothesis's modules, the editable finders).
unset PYTHONDONTWRITEBYTECODE

if [[ "${1:-}" == --fast ]]; then
  shift
  echo '== pytest (fast lane: tests/core, not slow)' >&2
  exec python -m pytest tests/core -m 'not slow' -n 2 --durations=15 "$@"
fi

echo '== ruff' >&2
ruff check src tests benchmarks scripts
echo '== mypy (strict)' >&2
# Every module is checked strictly, the ROS adapters too (rclpy ships its types; the nodes
# may call its few unannotated Node methods: pyproject.toml); an exclusion would go in
# `--exclude`, and `python scripts/typing_report.py` counts the lines on each side.
mypy \
  src/trust_av_common/trust_av_common src/preceding_traffic/preceding_traffic \
  src/trust_monitor/trust_monitor src/human_driver_sim/human_driver_sim \
  src/trust_av_planner/trust_av_planner src/trust_av/trust_av \
  src/trust_av_autoware/trust_av_autoware
echo '== docs (mkdocs build --strict)' >&2
docs_site="$(mktemp -d)"
bash scripts/build_docs.sh --site-dir "$docs_site"
rm -rf "$docs_site"
echo '== pytest' >&2
# Every Python process of the suite (about 800: node graphs, CLIs, workers) imports the
# project's modules: compiled once here, and the test modules rewritten by pytest once
# (--collect-only), rather than by the six workers at once, each for itself.
python -m compileall -q -j 0 src tests benchmarks scripts > /dev/null
python -m pytest --collect-only -q > /dev/null || true   # an error is the run's to report
python -m pytest -n 6 --dist loadgroup --no-loadscope-reorder --durations=15 "$@"
