#!/usr/bin/env bash
# The project's main job (README): set up .venv if needed, then run the closed loop on the
# shipped US06 drive cycle with the embedded defaults (config/trust_av.yaml) and print the
# metrics. Extra arguments go to `trust-av simulate`, e.g. `--alpha 1 --trace nycc`.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
source scripts/bootstrap.sh
mkdir -p runs
trust-av simulate --trace us06 --out runs/us06.csv "$@"
