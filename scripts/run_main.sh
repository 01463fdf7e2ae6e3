#!/usr/bin/env bash
# The project's main job (README): set up .venv if needed, then run the ROS 2 node graph on
# the shipped US06 drive cycle with the embedded defaults (config/trust_av.yaml), record it
# to the rosbag2 bag directory bags/main_us06/, print the metrics and write
# bags/main_us06.png. Extra arguments go to `trust-av run`, e.g. `--alpha 1 --trace nycc`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
source scripts/bootstrap.sh
trust-av run --trace us06 --bag bags/main_us06 --overwrite "$@"
