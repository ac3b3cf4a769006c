#!/usr/bin/env bash
# Sets fuzzyq up and reproduces the paper's simulation (section 3.1, figures 2-4) on its full
# fuzzy grid. Builds the `fuzzyq` command and installs the Python package into `.venv`; trains
# the joint Q-function (4,100,625 cores x 625 joint actions), rolls out the greedy and the
# interpolated policy from the paper's start [-4,-6,-2,2,5,3,2,-1], and writes the policy,
# figures, trajectories and metrics to results/paper/ (or the directory given); then reruns
# the paper's Table 1 (fuzzy against crisp learners) into results/paper/table1/.
set -euo pipefail
cd "$(dirname "$0")/.."

out=${1:-results/paper}
cargo build --release --locked -p fuzzyq-cli
./scripts/setup-python.sh .venv
mkdir -p "$out"
fuzzyq=target/release/fuzzyq

"$fuzzyq" train --env pointmass --out "$out/policy.fzq" --json "$out/train.json"
for kind in greedy interpolated; do
    "$fuzzyq" rollout --policy "$out/policy.fzq" --policy-kind "$kind" \
        --csv "$out/rollout-$kind.csv" --plot "$out/rollout-$kind.png" \
        --json "$out/rollout-$kind.json"
done
"$fuzzyq" compare --env pointmass --out "$out/table1"
echo "results in $out/; the Python package is in .venv (source .venv/bin/activate)"
