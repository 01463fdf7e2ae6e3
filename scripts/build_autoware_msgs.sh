#!/usr/bin/env bash
# Build the vendored Autoware message packages (vendor/autoware_perception_msgs,
# vendor/autoware_control_msgs: the messages the adapters of src/trust_av_autoware use) into a
# virtual environment. No wheel of them is published, so they are generated and compiled here
# with ament_cmake and the rosidl generators, as vendor/tf2_msgs is (the same pinned build
# tools, vendor/tf2_msgs/requirements-build.txt; needs cmake and a C/C++ compiler).
# A package of the same name that is already there (importable from the environment's Python,
# or in the ament index of a prefix on AMENT_PREFIX_PATH, e.g. a native Autoware) is never
# built over: it is skipped with one line. Usage: bash scripts/build_autoware_msgs.sh VENV
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$(cd "$1" && pwd)"
say() { echo "[bootstrap] $*" >&2; }

installed_elsewhere() {  # a package NAME on AMENT_PREFIX_PATH outside this environment
  local prefix
  IFS=: read -ra prefixes <<<"${AMENT_PREFIX_PATH:-}"
  for prefix in "${prefixes[@]}"; do
    [ -n "$prefix" ] && [ "$(cd "$prefix" 2>/dev/null && pwd)" != "$venv" ] \
      && [ -e "$prefix/share/ament_index/resource_index/packages/$1" ] && { echo "$prefix"; return 0; }
  done
  return 1
}

tools_installed=0
for name in autoware_control_msgs autoware_perception_msgs; do
  if "$venv/bin/python" -c "import $name.msg" 2>/dev/null; then
    say "$name: already importable, not built"
    continue
  fi
  if where=$(installed_elsewhere "$name"); then
    say "$name: installed in $where, not built over it"
    continue
  fi
  src="$root/vendor/$name"
  build="$(mktemp -d)"
  say "$name: building the message package (no wheel exists) into $venv: a minute or two"
  if [ "$tools_installed" = 0 ]; then
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check \
      -r "$root/vendor/tf2_msgs/requirements-build.txt" 2> >(grep -v "^WARNING: Location" >&2)
    tools_installed=1
  fi
  # the ament index the rosidl generators search for type supports: this environment's
  PATH="$venv/bin:$PATH" AMENT_PREFIX_PATH="$venv" cmake -S "$src" -B "$build" -DCMAKE_PREFIX_PATH="$venv" \
    -DCMAKE_INSTALL_PREFIX="$venv" -DPython3_EXECUTABLE="$venv/bin/python" -DBUILD_TESTING=OFF \
    > "$build/configure.log" 2>&1 || { cat "$build/configure.log" >&2; rm -rf "$build"; exit 1; }
  PATH="$venv/bin:$PATH" AMENT_PREFIX_PATH="$venv" cmake --build "$build" -j "$(nproc)" > "$build/build.log" 2>&1 \
    || { tail -50 "$build/build.log" >&2; rm -rf "$build"; exit 1; }
  cmake --install "$build" > /dev/null
  rm -rf "$build"
  "$venv/bin/python" -c "import $name.msg" \
    || { say "$name was built but does not import"; exit 1; }
  say "$name: built"
done
