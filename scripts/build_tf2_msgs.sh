#!/usr/bin/env bash
# Build tf2_msgs/msg/TFMessage (the graph's tf topic) into a virtual environment.
# No tf2_msgs wheel is published (the ros-jazzy-* wheels cover common_interfaces, which does
# not hold it), so vendor/tf2_msgs is generated and compiled here with ament_cmake and the
# rosidl generators (pinned in vendor/tf2_msgs/requirements-build.txt; needs cmake and a C/C++
# compiler). A native ROS 2 Jazzy install has the real package (ros-jazzy-tf2-msgs): never run
# this there. Usage: bash scripts/build_tf2_msgs.sh VENV
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
venv="$(cd "$1" && pwd)"
src="$root/vendor/tf2_msgs"
build="$(mktemp -d)"
trap 'rm -rf "$build"' EXIT
echo "[bootstrap] step 4/4: building the message package tf2_msgs (no wheel exists) into $venv: about a minute" >&2
echo "[bootstrap] tf2_msgs: installing the build tools (vendor/tf2_msgs/requirements-build.txt)" >&2
"$venv/bin/python" -m pip install --quiet --disable-pip-version-check -r "$src/requirements-build.txt" 2> >(grep -v "^WARNING: Location" >&2)
echo "[bootstrap] tf2_msgs: configuring (cmake)" >&2
export PATH="$venv/bin:$PATH"
cmake -S "$src" -B "$build" -DCMAKE_PREFIX_PATH="$venv" -DCMAKE_INSTALL_PREFIX="$venv" \
  -DPython3_EXECUTABLE="$venv/bin/python" -DBUILD_TESTING=OFF > "$build/configure.log" 2>&1 \
  || { cat "$build/configure.log" >&2; exit 1; }
# cmake's "[ 42%]" lines are the build's progress: shown every 10 %
cmake --build "$build" -j "$(nproc)" 2>&1 | tee "$build/build.log" | {
  shown=-10
  while IFS= read -r line; do
    if [[ "$line" =~ ^\[\ *([0-9]+)%\] ]] && [ "${BASH_REMATCH[1]}" -ge $((shown + 10)) ]; then
      shown=${BASH_REMATCH[1]}
      echo "[bootstrap] tf2_msgs: compiling, $shown %" >&2
    fi
  done
} || { tail -50 "$build/build.log" >&2; exit 1; }
cmake --install "$build" > /dev/null
"$venv/bin/python" -c 'from tf2_msgs.msg import TFMessage' \
  || { echo "[bootstrap] tf2_msgs was built but does not import" >&2; exit 1; }
