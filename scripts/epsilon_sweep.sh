#!/usr/bin/env bash
# The epsilon evidence of docs/RESULTS.md ("What epsilon changes"): `trust-av simulate` on US06
# with params files that differ from config/trust_av.yaml only in epsilon_mps2 (and, for the
# cost-scale rule, explicability_scale). One CSV row per run.
# Usage: bash scripts/epsilon_sweep.sh OUT_DIR "EPSILONS" "SCALES" "PREDICTORS" "ALPHAS"
#   e.g. bash scripts/epsilon_sweep.sh /tmp/eps "3 3.5 4 5 6" "0.005" "ca gru" "0 0.5 1"
# Writes OUT_DIR/eps<E>_scale<S>.yaml (the params files) and OUT_DIR/sweep.csv
# (epsilon, scale, predictor, alpha, final_trust, mean_E, rmse, fallbacks, unsafe_steps).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
out="${1:?output directory}"
epsilons="${2:-3 3.5 4 5 6}"
scales="${3:-0.005}"
predictors="${4:-ca gru}"
alphas="${5:-0 0.5 1}"
source "$root/scripts/bootstrap.sh"
mkdir -p "$out"
base="$root/config/trust_av.yaml"
grep -q '^    epsilon_mps2: 6.0 ' "$base" || { echo "$base: epsilon_mps2 line not found" >&2; exit 2; }
grep -q '^    explicability_scale: 0.005$' "$base" || {
  echo "$base: explicability_scale line not found" >&2; exit 2; }
csv="$out/sweep.csv"
[ -f "$csv" ] || echo 'epsilon,scale,predictor,alpha,final_trust,mean_E,rmse,fallbacks,unsafe_steps' > "$csv"
for eps in $epsilons; do
  for scale in $scales; do
    params="$out/eps${eps}_scale${scale}.yaml"
    sed -e "s/^    epsilon_mps2: 6.0 /    epsilon_mps2: ${eps} /" \
        -e "s/^    explicability_scale: 0.005$/    explicability_scale: ${scale}/" "$base" > "$params"
    # Exactly the two lines may differ from the default.
    changed="$(diff "$base" "$params" | grep -c '^>' || true)"
    [ "$changed" -le 2 ] || { echo "$params: $changed lines differ" >&2; exit 1; }
    for predictor in $predictors; do
      for alpha in $alphas; do
        text="$(trust-av simulate --trace us06 --predictor "$predictor" --alpha "$alpha" \
                 --params-file "$params" --no-progress)"
        field() { echo "$text" | grep "^$1" | awk '{print $NF}'; }
        echo "$eps,$scale,$predictor,$alpha,$(field 'final trust'),$(field 'mean explicability'),$(field 'prediction RMSE'),$(field 'NMPC fallback'),$(field 'unsafe steps')" | tee -a "$csv"
      done
    done
  done
done
