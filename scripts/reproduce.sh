#!/usr/bin/env bash
# Builds fuzzyq and reproduces the paper's simulation (section 3.1, figures 2-4) on its full
# fuzzy grid: trains the joint Q-function (4,100,625 cores x 625 joint actions), rolls out the
# greedy and the interpolated policy from the paper's start [-4,-6,-2,2,5,3,2,-1], and writes
# the policy, figures, trajectories and metrics to results/paper/ (or the directory given).
set -euo pipefail
cd "$(dirname "$0")/.."

out=${1:-results/paper}
cargo build --release --locked -p fuzzyq-cli
mkdir -p "$out"
fuzzyq=target/release/fuzzyq

"$fuzzyq" train --env pointmass --out "$out/policy.fzq" --json "$out/train.json"
for kind in greedy interpolated; do
    "$fuzzyq" rollout --policy "$out/policy.fzq" --policy-kind "$kind" \
        --csv "$out/rollout-$kind.csv" --plot "$out/rollout-$kind.png" \
        --json "$out/rollout-$kind.json"
done
echo "results in $out/"
