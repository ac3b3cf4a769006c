#!/usr/bin/env bash
# The GPU path checked on a Linux machine with a GPU, in a few minutes and without a Rust
# toolchain or the network: the GPU tests, full backups on the GPU and the CPU, and the
# default point-mass and Khepera runs on both (same policy bits?), then one table.
#
# Needs, built elsewhere (see the GPU section of BENCHMARKS.md for the commands):
#   FUZZYQ_BIN   the release binary            (default: .gpucheck/fuzzyq, else target/release/fuzzyq)
#   FUZZYQ_TESTS the integration-test binary   (default: .gpucheck/integration; skipped if absent)
# and the Vulkan loader: where `ldconfig -p` lists no libvulkan.so.1, the Debian package in
# .gl/ (`apt-get download libvulkan1` on a machine with the network) is unpacked into /.
# NVIDIA's Vulkan driver file is looked up where NVIDIA's container images put it.
# Logs and JSON go to $OUT (or ./gpu-check-out), and each table row to $OUT/rows.md as it is
# made (so a run cut short still reports). GPU_CHECK_ENVS and GPU_CHECK_BENCH_ENV choose
# smaller problems for a trial of the script itself (on lavapipe, say: `GPU_CHECK_ENVS=dcmotor
# GPU_CHECK_TRAIN_ARGS="--precision f32" GPU_CHECK_BENCH_ENV=dcmotor GPU_CHECK_BATCHES=256
# scripts/gpu-check.sh`; there the exports differ, as lavapipe does not fuse `fma`). Each
# train row is followed by where its seconds went, from its `--json` summary. Then three point
# masses on the paper's cores (45^6 = 8.3e9 cores; `V` in 23 parts on the card, about 108 GB
# of the host's memory) with 3 force levels per axis (729 joint actions): one full backup
# timed. Last, three point masses on a smaller grid (GPU_CHECK_THREE, a configuration; empty
# skips them): trained on the GPU and rolled out from 20 random starts, then one full backup
# with 5 force levels per axis.
# GPU_CHECK_KERNELS lists the full backup's other kernels timed beside the default (section 2).
# GPU_CHECK_UNTIL (below) runs several sections in the order a caller wants within one call.
# GPU_CHECK_SECTIONS picks sections (default "1 2 3 paper 4"). Three more, not run by default as
# each takes minutes (run them as calls of their own): "paper-5" times one full backup of the
# paper's cores with the paper's 5 forces per axis (15,625 joint actions; the H200's kernels
# of November 2026 would take about half an hour), "paper-train" trains three point masses
# on the paper's cores with forces of -0.2, 0 and 0.2 N per axis (729 joint actions) to the
# paper's xi on the GPU after a coarse start (every other core: 11.4M cores) (about 108 GB of the host's memory; the policy, about 48 GB, goes to
# GPU_CHECK_SCRATCH, default /tmp, not $OUT), and "paper-rollout" rolls that policy out from
# 20 starts and removes it.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-gpu-check-out}
mkdir -p "$OUT"
: >"$OUT/rows.md"
BIN=${FUZZYQ_BIN:-$( [ -x .gpucheck/fuzzyq ] && echo .gpucheck/fuzzyq || echo target/release/fuzzyq )}
TESTS=${FUZZYQ_TESTS:-.gpucheck/integration}
# GPU_CHECK_UNTIL (seconds since the epoch, optional): every step's time limit is cut to what is
# left before it, and sections not yet started when it has passed are skipped, so that one call
# of a lent machine can run several invocations of this script in the order it wants.
limit() {
  local t=$1
  if [ -n "${GPU_CHECK_UNTIL:-}" ]; then
    local left=$((GPU_CHECK_UNTIL - $(date +%s)))
    ((left < t)) && t=$left
  fi
  echo $((t > 1 ? t : 1))
}
want() {
  [[ " ${GPU_CHECK_SECTIONS:-1 2 3 paper 4} " == *" $1 "* ]] || return 1
  [ -z "${GPU_CHECK_UNTIL:-}" ] || (($(date +%s) + 5 < GPU_CHECK_UNTIL)) || { row "section $1" "SKIPPED" "out of time (GPU_CHECK_UNTIL)"; return 1; }
}
row() { printf '| %s | %s | %s |\n' "$1" "$2" "$3" >>"$OUT/rows.md"; }
now() { date +%s.%N; }
secs() { python3 -c "print(f'{$2 - $1:.2f}')" 2>/dev/null || echo "?"; }
# Where a run's time went, from its `train --json` summary: the device, the set-up, the coarse
# start, the sweeps (of which evaluation), the other passes (exact changes, greedy passes),
# the result read back, the policy written, and the command's total; the process's peak memory.
phases() {
  python3 - "$1" <<'PY' 2>/dev/null || echo "no summary"
import json, sys
d = json.load(open(sys.argv[1]))
g = lambda k: d.get(k) or 0.0
coarse = (d.get("coarse_start") or {}).get("seconds", 0.0)
other = g("seconds") - g("setup_seconds") - coarse - g("sweep_seconds") - g("result_seconds")
device = "device (beside setup)" if d.get("device_beside_setup") else "device"
parts = [(device, d.get("device_seconds")), ("setup", g("setup_seconds")), ("coarse", coarse),
         ("sweeps", g("sweep_seconds")), ("of them evaluation", g("evaluation_seconds")),
         ("other passes", other), ("result", g("result_seconds")), ("write", g("write_seconds"))]
peak = d.get("peak_memory_mb")
print(", ".join(f"{k} {v:.3f}" for k, v in parts if v is not None)
      + f" = command {g('command_seconds'):.3f} s"
      + (f"; peak memory {peak:.0f} MB" if peak else ""))
PY
}

# A GPU training run of configuration $2 writing policy $3, timed, within $1 seconds (its log
# $OUT/train-$4.log, its summary $OUT/$4.json): sets rc and wall.
timed_train() {
  local t0
  t0=$(now)
  timeout "$(limit "$1")" "$BIN" train --config "$2" --device gpu --out "$3" --json "$OUT/$4.json" >"$OUT/train-$4.log" 2>&1
  rc=$?
  wall=$(secs "$t0" "$(now)")
}

# The Vulkan loader, and NVIDIA's driver file.
if ! ldconfig -p 2>/dev/null | grep -q 'libvulkan.so.1'; then
  for f in .gl/*.deb; do [ -e "$f" ] && dpkg -x "$f" /; done
  ldconfig
fi
for icd in /usr/local/nvidia/share/vulkan/icd.d/nvidia_icd.json /usr/share/vulkan/icd.d/nvidia_icd.json /etc/vulkan/icd.d/nvidia_icd.json; do
  if [ -z "${VK_DRIVER_FILES:-}" ] && [ -e "$icd" ]; then export VK_DRIVER_FILES=$icd; fi
done
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-/tmp}
nproc_=$(nproc)
cpu=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//')
gpu=$(nvidia-smi --query-gpu=name,driver_version --format=csv,noheader 2>/dev/null | head -1)
row "host" "${gpu:-no nvidia-smi}" "$cpu, $nproc_ CPUs"

# 1. The GPU tests (bit for bit against the host reference, and against the CPU solver where
#    the adapter fuses).
if ! want 1; then
  :
elif [ -x "$TESTS" ]; then
  FUZZYQ_REQUIRE_GPU=1 timeout "$(limit 240)" "$TESTS" gpu:: --test-threads 4 >"$OUT/tests.log" 2>&1
  rc=$?
  res=$(grep -E '^test result' "$OUT/tests.log" | tail -1)
  row "GPU tests (integration gpu::)" "$([ $rc = 0 ] && echo PASS || echo "FAIL rc=$rc")" "${res:-no result line}"
  grep -m1 'GPU tests on' "$OUT/tests.log" | cut -c1-300 >"$OUT/adapter.txt" || true
else
  row "GPU tests" "SKIPPED" "no test binary at $TESTS"
fi

# 2. Full backups of the paper's grid on the GPU (several batch sizes) and on the CPU.
GPU_CHECK_BATCHES=${GPU_CHECK_BATCHES:-256 64 1024}
want 2 || GPU_CHECK_BATCHES=
for mb in $GPU_CHECK_BATCHES; do
  FUZZYQ_GPU_PROFILE=$([ "$mb" = "${GPU_CHECK_BATCHES%% *}" ] && echo 1) FUZZYQ_GPU_BATCH_MB=$mb timeout "$(limit 120)" "$BIN" bench --env "${GPU_CHECK_BENCH_ENV:-pointmass}" --device gpu --backups 6 --peak-seconds 0.5 \
    --json "$OUT/bench-gpu-$mb.json" >"$OUT/bench-gpu-$mb.log" 2>&1
  rc=$?
  line=$(grep -E '^(backup|evaluate|read back|problem)' "$OUT/bench-gpu-$mb.log" | sed 's/  */ /g' | paste -sd ';' -)
  peak=$(grep -E '^FMA peak' "$OUT/bench-gpu-$mb.log" | sed 's/^FMA peak *//')
  opened=$(grep -oE 'opened in [^)]*\)' "$OUT/bench-gpu-$mb.log")
  row "GPU full backup, batch ${mb} MiB" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" "${line:-see log}; peak ${peak}; GPU ${opened}"
  prof=$(grep -E '^profile' "$OUT/bench-gpu-$mb.log" | sed 's/^profile *//' | paste -sd ';' -)
  [ -n "$prof" ] && row "  its dispatches, one at a time" "" "$prof"
done
# The other kernels of a full backup, each pair STAGES/LAST with its dispatches timed one at a
# time: the stages before the last (FUZZYQ_GPU_STAGES: rows, or merged) and the fused last
# stage (FUZZYQ_GPU_LAST: rows; merged:N, N cores in turn; tile:T, a workgroup of T threads
# per item of the stage before, its values in workgroup memory; unrolled, the last block's
# rows compiled into the kernel; joined, that kernel computing the stage before it itself,
# which is then not dispatched; staged:T, a workgroup of T threads per item of the stage
# before computing that item's values into workgroup memory, rows read from the tables, not
# compiled in, first as it is not yet timed on a GPU; staged:T:C, C of the item's columns a
# pass). FUZZYQ_GPU_STAGES=unrolled compiles each earlier stage's
# rows in. The rows above use the default on a GPU for a problem of this size (below 1e11
# multiply-adds per full backup), merged/rows; rows/rows are the kernels before the merge.
# A third field, STAGES/LAST/0, turns the reductions by subgroup off (FUZZYQ_GPU_SUBGROUPS=0);
# a fourth, STAGES/LAST//all, compiles the kernels with every one of wgpu's runtime checks
# (FUZZYQ_GPU_CHECKS=all; by default none), to time what they cost.
GPU_CHECK_KERNELS=${GPU_CHECK_KERNELS:-merged/staged unrolled/staged merged/staged:128 merged/staged:512 merged/staged:1024 merged/staged:256:32 unrolled/unrolled unrolled/joined merged/unrolled unrolled/rows rows/rows unrolled/unrolled/0 merged/rows/0 merged/rows//all unrolled/unrolled//all merged/staged//all}
want 2 || GPU_CHECK_KERNELS=
for kern in $GPU_CHECK_KERNELS; do
  log="$OUT/bench-gpu-kernels-$(echo "$kern" | tr '/:' '--').log"
  IFS=/ read -r stages rest sg checks <<<"$kern"
  FUZZYQ_GPU_CHECKS=$checks FUZZYQ_GPU_SUBGROUPS=$sg FUZZYQ_GPU_PROFILE=1 FUZZYQ_GPU_STAGES=$stages FUZZYQ_GPU_LAST=$rest timeout "$(limit 120)" "$BIN" bench --env "${GPU_CHECK_BENCH_ENV:-pointmass}" \
    --device gpu --backups 6 --evaluations 0 --peak-seconds 0.1 --json "${log%.log}.json" >"$log" 2>&1
  rc=$?
  row "GPU full backup, kernels $kern" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
    "$(grep -E '^(backup|profile)' "$log" | sed -e 's/  */ /g' -e 's/^profile //' | paste -sd ';' -);$(grep -oE 'set-up [0-9.]+ s \(compiling kernels [0-9.]+ s\)' "$log")"
done
# Policy evaluation split at each of GPU_CHECK_EVALS (FUZZYQ_GPU_EVAL: nested, every block per
# core over V; stages:K, the first K stages of a full backup for every action, then the other
# blocks per core; auto, the least estimated work), the stages with the kernels
# GPU_CHECK_EVAL_STAGES (FUZZYQ_GPU_STAGES, default unrolled: auto then runs two stages).
GPU_CHECK_EVALS=${GPU_CHECK_EVALS:-nested stages:1 stages:2 auto}
want 2 || GPU_CHECK_EVALS=
for ev in $GPU_CHECK_EVALS; do
  log="$OUT/bench-gpu-eval-$(echo "$ev" | tr ':' '-').log"
  FUZZYQ_GPU_EVAL=$ev FUZZYQ_GPU_STAGES=${GPU_CHECK_EVAL_STAGES:-unrolled} timeout "$(limit 120)" "$BIN" bench --env "${GPU_CHECK_BENCH_ENV:-pointmass}" \
    --device gpu --backups 1 --evaluations 5 --peak-seconds 0.1 --json "${log%.log}.json" >"$log" 2>&1
  rc=$?
  row "GPU evaluation sweep, split $ev" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
    "$(grep -E '^evaluate' "$log" | sed -e 's/  */ /g' -e 's/^evaluate //')"
done
# The robots' grid on the GPU, profiled.
if want 2 && [ -z "${GPU_CHECK_BENCH_ENV:-}" ]; then
  FUZZYQ_GPU_PROFILE=1 timeout "$(limit 120)" "$BIN" bench --env khepera --device gpu --backups 4 --peak-seconds 0.2 \
    --json "$OUT/bench-gpu-khepera.json" >"$OUT/bench-gpu-khepera.log" 2>&1
  rc=$?
  row "GPU full backup, khepera" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" "$(grep -E '^(backup|evaluate|read back|profile)' "$OUT/bench-gpu-khepera.log" | sed 's/  */ /g' | paste -sd ';' -)"
fi
if want 2; then
  timeout "$(limit 120)" "$BIN" bench --env "${GPU_CHECK_BENCH_ENV:-pointmass}" --backups 4 --peak-seconds 0.5 --json "$OUT/bench-cpu.json" >"$OUT/bench-cpu.log" 2>&1
  rc=$?
  row "CPU full backup ($nproc_ threads)" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" "$(grep -E '^backup' "$OUT/bench-cpu.log" | sed 's/^backup *//')"
fi

# 3. The default runs on both devices: wall time and the same values and greedy actions
#    (the exported policies, which hold V and the greedy actions, compared byte for byte).
want 3 || GPU_CHECK_ENVS=" "
for env in ${GPU_CHECK_ENVS:-pointmass khepera}; do
  for dev in gpu cpu; do
    t0=$(now)
    timeout "$(limit 180)" "$BIN" train --env "$env" --device "$dev" ${GPU_CHECK_TRAIN_ARGS:-} --out "$OUT/$env-$dev.fzq" \
      --json "$OUT/$env-$dev.json" >"$OUT/train-$env-$dev.log" 2>&1
    rc=$?
    t1=$(now)
    wall=$(secs "$t0" "$t1")
    eval "rc_$dev=$rc; wall_$dev=$wall"
    [ $rc = 0 ] && "$BIN" export --policy "$OUT/$env-$dev.fzq" --out "$OUT/$env-$dev.bin" >/dev/null 2>&1
  done
  same="differ"
  if [ -s "$OUT/$env-gpu.bin" ] && cmp -s "$OUT/$env-gpu.bin" "$OUT/$env-cpu.bin"; then same="identical"; fi
  sweeps=$(grep -E 'sweeps|converged' "$OUT/train-$env-gpu.log" | tail -1 | cut -c1-120)
  row "train --env $env" "$([ "$rc_gpu" = 0 ] && [ "$same" = identical ] && echo PASS || echo "FAIL (gpu rc=$rc_gpu, exports $same)")" \
    "gpu ${wall_gpu} s wall, cpu ${wall_cpu} s wall; exported V + greedy $same; ${sweeps}"
  for dev in gpu cpu; do
    row "  its seconds on the $dev" "" "$(phases "$OUT/$env-$dev.json")"
  done
  # V cut into parts of 1 MiB (about two slabs each: 23 parts on the paper's grid) where one
  # would do: the same bytes.
  if [ "$env" = pointmass ]; then
    FUZZYQ_GPU_PART_KB=1024 timeout "$(limit 180)" "$BIN" train --env "$env" --device gpu ${GPU_CHECK_TRAIN_ARGS:-} \
      --out "$OUT/$env-parts.fzq" >"$OUT/train-$env-parts.log" 2>&1
    rc=$?
    [ $rc = 0 ] && "$BIN" export --policy "$OUT/$env-parts.fzq" --out "$OUT/$env-parts.bin" >/dev/null 2>&1
    same="differ"
    if [ -s "$OUT/$env-parts.bin" ] && cmp -s "$OUT/$env-parts.bin" "$OUT/$env-cpu.bin"; then same="identical"; fi
    row "train --env $env, V in parts of 1 MiB" "$([ $rc = 0 ] && [ "$same" = identical ] && echo PASS || echo "FAIL (rc=$rc, exports $same)")" \
      "exported V + greedy against the cpu's: $same"
    # The GPU opened before the set-up instead of beside it (the default for this run).
    t0=$(now)
    FUZZYQ_GPU_OPEN=first timeout "$(limit 180)" "$BIN" train --env "$env" --device gpu ${GPU_CHECK_TRAIN_ARGS:-} \
      --out "$OUT/$env-first.fzq" --json "$OUT/$env-first.json" >"$OUT/train-$env-first.log" 2>&1
    rc=$?
    wall=$(secs "$t0" "$(now)")
    row "train --env $env, GPU opened first" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
      "gpu ${wall} s wall (beside the set-up: ${wall_gpu} s); $(phases "$OUT/$env-first.json")"
  fi
  # Other kernels (GPU_CHECK_TRAIN_KERNELS, STAGES/LAST each; empty skips them): the stages
  # merged and the last stage staged (no rows compiled in), then every stage's rows compiled
  # into its kernel: the wall time and the CPU's bytes.
  for kern in ${GPU_CHECK_TRAIN_KERNELS-merged/staged unrolled/unrolled}; do
    tag=$(echo "$kern" | tr '/:' '--')
    t0=$(now)
    FUZZYQ_GPU_STAGES=${kern%%/*} FUZZYQ_GPU_LAST=${kern#*/} timeout "$(limit 180)" "$BIN" train --env "$env" --device gpu \
      ${GPU_CHECK_TRAIN_ARGS:-} --out "$OUT/$env-kern-$tag.fzq" --json "$OUT/$env-kern-$tag.json" >"$OUT/train-$env-kern-$tag.log" 2>&1
    rc=$?
    wall=$(secs "$t0" "$(now)")
    [ $rc = 0 ] && "$BIN" export --policy "$OUT/$env-kern-$tag.fzq" --out "$OUT/$env-kern-$tag.bin" >/dev/null 2>&1
    same="differ"
    if [ -s "$OUT/$env-kern-$tag.bin" ] && cmp -s "$OUT/$env-kern-$tag.bin" "$OUT/$env-cpu.bin"; then same="identical"; fi
    row "train --env $env, kernels $kern" "$([ $rc = 0 ] && [ "$same" = identical ] && echo PASS || echo "FAIL (rc=$rc, exports $same)")" \
      "gpu ${wall} s wall; exported V + greedy against the cpu's: $same; $(phases "$OUT/$env-kern-$tag.json")"
    # Once more, the driver's cache of compiled kernels now warm (a user's second run): the
    # set-up that decides whether compiling the rows in pays at this size (COMPILE_IN_FROM).
    t0=$(now)
    FUZZYQ_GPU_STAGES=${kern%%/*} FUZZYQ_GPU_LAST=${kern#*/} timeout "$(limit 180)" "$BIN" train --env "$env" --device gpu \
      ${GPU_CHECK_TRAIN_ARGS:-} --out "$OUT/$env-kern2-$tag.fzq" --json "$OUT/$env-kern2-$tag.json" >"$OUT/train-$env-kern2-$tag.log" 2>&1
    rc=$?
    wall=$(secs "$t0" "$(now)")
    row "train --env $env, kernels $kern, again" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
      "gpu ${wall} s wall; $(phases "$OUT/$env-kern2-$tag.json")"
  done
done

# The paper's three point masses: 45^6 cores, V in 23 parts on the card, one slab's first
# stage (3.69 GB) in parts; 3 forces per axis (729 joint actions), or the paper's 5 (15,625);
# the kernels GPU_CHECK_PAPER_KERNELS (STAGES/LAST, default unrolled/unrolled).
for sec in paper paper-5; do
  if [ $sec = paper ]; then
    want paper || continue
    forces='s/^force_levels = .*/force_levels = [-0.2, 0.0, 0.2]/' cap=240
  else
    [[ " ${GPU_CHECK_SECTIONS:-} " == *" paper-5 "* ]] || continue
    forces='' cap=560
  fi
  "$BIN" config --env pointmass | sed "s/^agents = 2 /agents = 3 /; $forces" >"$OUT/$sec-three.toml"
  kern=${GPU_CHECK_PAPER_KERNELS:-unrolled/unrolled}
  FUZZYQ_GPU_STAGES=${kern%%/*} FUZZYQ_GPU_LAST=${kern#*/} timeout "$(limit $cap)" "$BIN" bench --config "$OUT/$sec-three.toml" --device gpu --backups 1 --evaluations 0 \
    --peak-seconds 0.2 --json "$OUT/bench-$sec-three.json" >"$OUT/bench-$sec-three.log" 2>&1
  rc=$?
  row "GPU full backup, three point masses on the paper's cores ($sec, kernels $kern)" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
    "$(grep -E '^(backup|problem|read back)|error' "$OUT/bench-$sec-three.log" | sed 's/  */ /g' | paste -sd ';' -)"
done

# 4. Three point masses: six blocks, so batches below fixed cores of the first blocks.
THREE=${GPU_CHECK_THREE-examples/three-point-masses.toml}
if want 4 && [ -n "$THREE" ]; then
  timed_train 240 "$THREE" "$OUT/three.fzq" three
  sweeps=$(grep -E 'converged|sweeps' "$OUT/train-three.log" | tail -1 | cut -c1-140)
  reach="no policy"
  if [ $rc = 0 ]; then
    timeout "$(limit 60)" "$BIN" rollout --policy "$OUT/three.fzq" --starts 20 >"$OUT/rollout-three.log" 2>&1
    reach=$(tail -1 "$OUT/rollout-three.log" | cut -c1-160)
  fi
  row "train $THREE (three point masses)" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
    "gpu ${wall} s wall; ${sweeps}; ${reach}"
  row "  its seconds on the gpu" "" "$(phases "$OUT/three.json")"
  # Its evaluation sweeps nested per core (as before) and split by least work.
  for ev in nested auto; do
    FUZZYQ_GPU_EVAL=$ev timeout "$(limit 90)" "$BIN" bench --config "$THREE" --device gpu --backups 1 --evaluations 3 \
      --peak-seconds 0.1 >"$OUT/bench-three-eval-$ev.log" 2>&1
    rc=$?
    row "  its evaluation sweeps, split $ev" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
      "$(grep -E '^(evaluate|backup)' "$OUT/bench-three-eval-$ev.log" | sed 's/  */ /g' | paste -sd ';' -)"
  done
  # The same grid with the paper's 5 force levels per axis: one full backup, with the default
  # kernels (its last stage too large to compile in: one row at a time) and with the last
  # stage staged (3,125 product columns per item, taken a few hundred at a time).
  sed 's/^force_levels = .*/force_levels = [-2.0, -0.2, 0.0, 0.2, 2.0]/' "$THREE" >"$OUT/three-5.toml"
  for kern in default unrolled/staged; do
    tag=$(echo "$kern" | tr '/:' '--')
    stages= last=
    [ "$kern" = default ] || stages=${kern%%/*} last=${kern#*/}
    FUZZYQ_GPU_PROFILE=1 FUZZYQ_GPU_STAGES=$stages FUZZYQ_GPU_LAST=$last timeout "$(limit 150)" "$BIN" bench --config "$OUT/three-5.toml" \
      --device gpu --backups 1 --evaluations 0 --peak-seconds 0.2 --json "$OUT/bench-three-5-$tag.json" >"$OUT/bench-three-5-$tag.log" 2>&1
    rc=$?
    row "GPU full backup, three point masses, 5 forces per axis, kernels $kern" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
      "$(grep -E '^(backup|problem|profile)' "$OUT/bench-three-5-$tag.log" | sed -e 's/  */ /g' -e 's/^profile //' | paste -sd ';' -)"
  done
fi

# The paper's three point masses trained on the GPU (opt-in: minutes), then rolled out from
# the policy that run left in the scratch folder (a section of its own, so that each fits one
# call of at most 10 minutes), which is then removed.
scratch=${GPU_CHECK_SCRATCH:-/tmp}
if [[ " ${GPU_CHECK_SECTIONS:-} " == *" paper-train "* ]]; then
  "$BIN" config --env pointmass \
    | sed 's/^agents = 2 /agents = 3 /; s/^force_levels = .*/force_levels = [-0.2, 0.0, 0.2]/; s/^coarse_start = false /coarse_start = true /' \
    >"$OUT/paper-three-3f.toml"
  timed_train 560 "$OUT/paper-three-3f.toml" "$scratch/paper-three.fzq" paper-three
  sweeps=$(grep -E 'converged|sweeps|error' "$OUT/train-paper-three.log" | tail -1 | cut -c1-160)
  size=$(stat -c %s "$scratch/paper-three.fzq" 2>/dev/null || echo none)
  row "train three point masses on the paper's cores, 3 forces per axis" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
    "gpu ${wall} s wall; ${sweeps}; policy file ${size} bytes"
  row "  its seconds on the gpu" "" "$(phases "$OUT/paper-three.json")"
fi
if [[ " ${GPU_CHECK_SECTIONS:-} " == *" paper-rollout "* ]]; then
  t0=$(now)
  peak=()
  [ -x /usr/bin/time ] && peak=(/usr/bin/time -f "peak memory %M KB")
  timeout "$(limit 560)" "${peak[@]}" "$BIN" rollout --policy "$scratch/paper-three.fzq" --starts 20 \
    >"$OUT/rollout-paper-three.log" 2>&1
  rc=$?
  wall=$(secs "$t0" "$(now)")
  rm -f "$scratch/paper-three.fzq"
  row "roll out three point masses on the paper's cores from 20 starts" "$([ $rc = 0 ] && echo ok || echo "FAIL rc=$rc")" \
    "${wall} s wall; $(grep -vE '^(peak|Command exited)' "$OUT/rollout-paper-three.log" | tail -1 | cut -c1-160); $(grep '^peak' "$OUT/rollout-paper-three.log")"
fi

echo
echo "| check | result | figures |"
echo "|---|---|---|"
tee "$OUT/table.md" <"$OUT/rows.md"
if [ -s "$OUT/adapter.txt" ]; then cat "$OUT/adapter.txt"; fi
