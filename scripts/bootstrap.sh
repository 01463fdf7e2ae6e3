#!/usr/bin/env bash
# Create (or reuse) the project's virtual environment in .venv and install everything the
# project needs from its own files: requirements.txt (all pins) and the packages in src/.
# Re-installs only when requirements.txt or a package's setup files changed (stamp file).
# Usage: source from the other scripts, or run it alone: bash scripts/bootstrap.sh
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="${TRUST_AV_VENV:-$root/.venv}"
python_bin="${PYTHON:-python3.11}"
command -v "$python_bin" >/dev/null 2>&1 || python_bin=python3
packages=(trust_av_common preceding_traffic trust_monitor human_driver_sim trust_av_planner trust_av trust_av_autoware)

stamp_inputs() {
  cat "$root/requirements.txt"
  for p in "${packages[@]}"; do cat "$root/src/$p/setup.py" "$root/src/$p/setup.cfg" "$root/src/$p/package.xml"; done
}
want="$(stamp_inputs | sha256sum | cut -d' ' -f1)"
stamp="$venv/.trust_av_stamp"

# Every step says what it does, how far it is and how long it took: pip's lines are counted
# (every 25th requirement named), the tf2_msgs build shows cmake's percentage.
say() { echo "[bootstrap] $*" >&2; }

# pip install "$@", its output reduced to a count of the requirements it has gone through
# (label $1, expected count $2); pip's whole output is kept in the file $3.
pip_counted() {
  local label="$1" total="$2" log="$3"; shift 3
  "$venv/bin/python" -m pip install --disable-pip-version-check --progress-bar off "$@" \
    2> >(grep -v "^WARNING: Location" >&2) | tee "$log" | {
    local n=0 line name
    while IFS= read -r line; do
      case "$line" in
        "Collecting "*|"Requirement already satisfied: "*|"Processing "*)
          n=$((n + 1)); name="${line#Collecting }"; name="${name#Requirement already satisfied: }"
          name="${name#Processing }"; name="${name%% *}"; name="${name##*/}"
          [ "$n" -gt "$total" ] && total=$n   # a requirement that pulls in one more
          [ $((n % 25)) = 0 ] && say "$label: $n/$total ($name)" ;;
        "Installing collected packages: "*)
          say "$label: installing $(( $(tr -cd , <<<"$line" | wc -c) + 1 )) packages (pip shows nothing while it unpacks: counted every 10 s)" ;;
      esac
    done
    true
  }
}

if [ ! -x "$venv/bin/python" ]; then
  say "step 1/4: creating the virtual environment $venv ($("$python_bin" --version))"
  "$python_bin" -m venv "$venv"
fi
# colcon never crawls the environment (its share/ holds the message wheels' package.xml files):
# a clone in a colcon workspace (docs/operations/colcon.md) builds only the packages of src/
[ -f "$venv/COLCON_IGNORE" ] || touch "$venv/COLCON_IGNORE"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  # the pins need CPython 3.11.5 or a later 3.11 (pymdown-extensions 13.1.2, for one); Debian
  # 12's python3 is 3.11.2: say so in one line instead of pip's page of versions
  if ! "$venv/bin/python" -c 'import sys; sys.exit(not (3, 11, 5) <= sys.version_info[:3] < (3, 12))'; then
    say "error: $venv has $("$venv/bin/python" --version 2>&1); the pinned dependencies need Python 3.11.5 or a later 3.11: remove $venv and run again with PYTHON=/path/to/that/python"
    exit 2
  fi
  setup_began=$SECONDS
  pins=$(grep -c '^[A-Za-z0-9].*==' "$root/requirements.txt")
  say "step 2/4: installing $pins pinned dependencies (requirements.txt; with pip's cache warm about a minute, cold a few)"
  # pip prints nothing while it unpacks (minutes for torch on a busy machine): count the
  # installed distributions every 10 s meanwhile
  site="$("$venv/bin/python" -c 'import sysconfig; print(sysconfig.get_path("purelib"))')"
  ( last=""
    while sleep 10 && kill -0 $$ 2>/dev/null; do   # ends with this shell, whatever happens
      count=$(find "$site" -maxdepth 1 -name '*.dist-info' | wc -l)
      [ "$count" != "$last" ] && [ -n "$last" ] && say "dependencies: $count distributions installed so far"
      last=$count
    done ) &
  watcher=$!
  # pip byte-compiles what it installs (about 25 CPU-s, torch's tree included), and that is
  # kept: --no-compile left every process compiling what it imports again where
  # PYTHONDONTWRITEBYTECODE is set (a fresh-clone suite took 560 s instead of 375), and
  # importing the project's modules once with writing on misses what torch and matplotlib
  # import lazily (sympy, backends: 1,000 modules in a short run of the suite).
  # requirements.txt pins the whole closure (pip check below proves it), so pip resolves
  # nothing (--no-deps). It is installed by two pip processes side by side, each with every
  # other pin: each waits on the index and unpacks and compiles on its own core (43-47 s
  # instead of 57-96 s for one process on 2 cores here). Disjoint sets of wheels, none built
  # from source, none that pip itself runs on (setuptools is replaced by one of them and
  # imported by neither), and no file installed by two of them
  # (tests/core/test_setup_pins.py).
  halves="$(mktemp -d)"
  grep '^[A-Za-z0-9].*==' "$root/requirements.txt" \
    | awk -v dir="$halves" '{ print > (dir "/" (NR % 2 ? 1 : 2) ".txt") }'
  pip_counted "dependencies (1 of 2)" "$(wc -l < "$halves/1.txt")" "$venv/pip-install-1.log" \
    --no-deps -r "$halves/1.txt" &
  first=$!
  failed=()     # both are waited for: nothing goes on writing into the environment
  pip_counted "dependencies (2 of 2)" "$(wc -l < "$halves/2.txt")" "$venv/pip-install-2.log" \
    --no-deps -r "$halves/2.txt" || failed+=("$venv/pip-install-2.log")
  wait "$first" || failed+=("$venv/pip-install-1.log")
  rm -r "$halves"
  if [ "${#failed[@]}" -gt 0 ]; then
    say "error: pip failed; its output: ${failed[*]}"
    exit 1
  fi
  kill "$watcher" 2>/dev/null || true
  wait "$watcher" 2>/dev/null || true
  say "step 2/4 done in $((SECONDS - setup_began)) s"
  step_began=$SECONDS
  say "step 3/4: installing the ${#packages[@]} project packages (editable: ${packages[*]})"
  args=()
  for p in "${packages[@]}"; do args+=(-e "$root/src/$p"); done
  "$venv/bin/python" -m pip install --quiet --disable-pip-version-check --no-deps --no-build-isolation "${args[@]}" 2> >(grep -v "^WARNING: Location" >&2)
  if ! broken="$("$venv/bin/python" -m pip check 2>&1)"; then
    say "error: requirements.txt is not a complete set of pins (pip check: $(tr '\n' ';' <<<"$broken"))"
    exit 1
  fi
  say "step 3/4 done in $((SECONDS - step_began)) s"
  # tf2_msgs has no wheel: built from vendor/tf2_msgs (about a minute, once per environment)
  if "$venv/bin/python" -c 'import tf2_msgs.msg' 2>/dev/null; then
    say "step 4/4: tf2_msgs is already built"
  else
    step_began=$SECONDS
    bash "$root/scripts/build_tf2_msgs.sh" "$venv"
    say "step 4/4 done in $((SECONDS - step_began)) s"
  fi
  echo "$want" > "$stamp"
  say "set-up done in $((SECONDS - setup_began)) s"
fi
# The Autoware message packages the adapters use (src/trust_av_autoware) have no wheel either:
# built from vendor/ (a minute; skipped where a package of the name is installed). The main job
# (scripts/run_main.sh) does not use the adapters and sets TRUST_AV_AUTOWARE_MSGS=0 so that a
# first run does not wait for them; the test command and a plain set-up build them.
if [ "${TRUST_AV_AUTOWARE_MSGS:-1}" = 1 ] \
    && ! "$venv/bin/python" -c 'import autoware_control_msgs.msg, autoware_perception_msgs.msg' 2>/dev/null; then
  step_began=$SECONDS
  bash "$root/scripts/build_autoware_msgs.sh" "$venv"
  say "Autoware message packages done in $((SECONDS - step_began)) s"
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
