#!/usr/bin/env bash
# Create (or reuse) the project's virtual environment in .venv and install everything the
# project needs from its own files: requirements.txt (all pins) and the four packages in src/.
# Re-installs only when requirements.txt or a package's setup files changed (stamp file).
# Usage: source from the other scripts, or run it alone: bash scripts/bootstrap.sh
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${TRUST_AV_VENV:-$root/.venv}"
python_bin="${PYTHON:-python3.11}"
command -v "$python_bin" >/dev/null 2>&1 || python_bin=python3
packages=(preceding_traffic trust_monitor human_driver_sim trust_av_planner)

stamp_inputs() {
  cat "$root/requirements.txt"
  for p in "${packages[@]}"; do cat "$root/src/$p/setup.py" "$root/src/$p/setup.cfg" "$root/src/$p/package.xml"; done
}
want="$(stamp_inputs | sha256sum | cut -d' ' -f1)"
stamp="$venv/.trust_av_stamp"

if [ ! -x "$venv/bin/python" ]; then
  echo "[bootstrap] creating virtual environment $venv ($("$python_bin" --version))" >&2
  "$python_bin" -m venv "$venv"
fi
# colcon never crawls the environment (its share/ holds the message wheels' package.xml files):
# a clone in a colcon workspace (docs/operations/colcon.md) builds only the four packages
[ -f "$venv/COLCON_IGNORE" ] || touch "$venv/COLCON_IGNORE"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  # the pins need CPython 3.11.5 or a later 3.11 (pymdown-extensions 13.1.2, for one); Debian
  # 12's python3 is 3.11.2: say so in one line instead of pip's page of versions
  if ! "$venv/bin/python" -c 'import sys; sys.exit(not (3, 11, 5) <= sys.version_info[:3] < (3, 12))'; then
    echo "[bootstrap] error: $venv has $("$venv/bin/python" --version 2>&1); the pinned dependencies need Python 3.11.5 or a later 3.11: remove $venv and run again with PYTHON=/path/to/that/python" >&2
    exit 2
  fi
  echo "[bootstrap] installing pinned dependencies (first run takes about a minute)" >&2
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$root/requirements.txt" 2> >(grep -v "^WARNING: Location" >&2)
  args=()
  for p in "${packages[@]}"; do args+=(-e "$root/src/$p"); done
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation "${args[@]}" 2> >(grep -v "^WARNING: Location" >&2)
  # tf2_msgs has no wheel: built from vendor/tf2_msgs (about a minute, once per environment)
  "$venv/bin/python" -c 'import tf2_msgs.msg' 2>/dev/null || bash "$root/scripts/build_tf2_msgs.sh" "$venv"
  echo "$want" > "$stamp"
fi
# The driver-in-the-loop tests drive Debian's chromium through Playwright (never a downloaded
# browser); installed when absent and when this runs as root (CI), quietly.
if [ ! -x /usr/bin/chromium ] && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
  echo "[bootstrap] installing Debian's chromium for the browser tests" >&2
  { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium; } \
    >/dev/null 2>&1 || echo "[bootstrap] chromium could not be installed: the browser tests skip" >&2
fi
export PATH="$venv/bin:$PATH"
export VIRTUAL_ENV="$venv"
