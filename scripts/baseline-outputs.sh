#!/usr/bin/env bash
# Records what a refactoring must not change: the policy files and the metrics (JSON with its
# timing fields left out) of `fuzzyq train`/`rollout` for every environment and learner and of
# `fuzzyq compare`, as one line per output: a SHA-256 prefix and the file's name.
#
#   F=path/to/fuzzyq scripts/baseline-outputs.sh /tmp/before > before.txt   # before the change
#   F=path/to/fuzzyq scripts/baseline-outputs.sh /tmp/after > after.txt     # after it
#   diff before.txt after.txt                                              # nothing: unchanged
#
# F defaults to target/release/fuzzyq. Takes about 20 s on 2 cores (release build).
set -euo pipefail
F=${F:-$(cd "$(dirname "$0")/.." && pwd)/target/release/fuzzyq}
out=$1
rm -rf "$out"
mkdir -p "$out"
cd "$out"
"$F" config --env khepera | sed -E 's/^position_cores = \[.*\]/position_cores = [-6.0, -1.5, 0.0, 1.5, 6.0]/; s/^heading_divisions = [0-9]+/heading_divisions = 6/' > k.toml
"$F" config --env pointmass | sed -E 's/^agents = 2/agents = 1/' > one.toml
"$F" train --env pointmass --out pm.fzq --json pm.json -q
"$F" train --env khepera --config k.toml --out k.fzq --json k.json -q
for e in dcmotor pendulum carhill arm; do "$F" train --env $e --out $e.fzq --json $e.json -q; done
"$F" train --env pointmass --config one.toml --learner fql --episodes 300 --out fql.fzq --json fql.json -q
"$F" train --env pointmass --config one.toml --learner vqql --episodes 300 --out vqql.fzq --json vqql.json -q
"$F" train --env pointmass --config one.toml --learner learned-model --samples 3000 --out lm.fzq --json lm.json -q
"$F" train --env pointmass --config one.toml --max-sweeps 7 --out ms.fzq --json ms.json -q
for p in pm dcmotor pendulum carhill arm; do "$F" rollout --policy $p.fzq --json r-$p.json --csv r-$p.csv -q; done
for p in fql vqql lm; do "$F" rollout --policy $p.fzq --x0=-4,5,0,0 --json r-$p.json --csv r-$p.csv -q; done
"$F" rollout --policy pm.fzq --policy-kind interpolated --json ri-pm.json -q
"$F" rollout --policy k.fzq --json r-k.json -q
"$F" rollout --policy pm.fzq --starts 4 --json rs-pm.json -q
"$F" compare --config one.toml --x0=-4,5,0,0 --starts 4 --steps 60 --episodes 40 --cells 32 \
    --samples 1000 --curve 100,1000 --out cmp > cmp.txt 2>/dev/null
python3 - <<'PY'
import hashlib, json, pathlib

TIMING = ("seconds", "memory", "gflops", "threads", "fuzzyq_version")
SKIP = ("cmp.txt", "table1.md", "table1.csv", "efficiency.csv")  # these print timings


def strip(o):
    if isinstance(o, dict):
        return {k: strip(v) for k, v in o.items() if not any(t in k for t in TIMING)}
    if isinstance(o, list):
        return [strip(v) for v in o]
    return o


for p in sorted(pathlib.Path(".").rglob("*")):
    if p.is_dir() or p.suffix in (".png", ".svg") or p.name in SKIP:
        continue
    b = p.read_bytes()
    if p.suffix == ".json":
        b = json.dumps(strip(json.loads(b)), sort_keys=True).encode()
    print(hashlib.sha256(b).hexdigest()[:16], p)
PY
