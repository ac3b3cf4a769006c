#!/usr/bin/env bash
# Builds the fuzzyq wheel that installs in seconds with no Rust toolchain: one abi3 wheel
# (CPython 3.11 and newer) for manylinux2014 (glibc 2.17 or newer) on this machine's
# architecture, carrying the Python package, the extension and the `fuzzyq` command line
# (`fuzzyq ...` and `python -m fuzzyq ...` after `pip install`). Zig, from PyPI's `ziglang`,
# links against the old glibc, so any Linux host with a Rust toolchain builds it.
#
#   ./scripts/build-wheels.sh [OUT_DIR]      # default: dist/
#   pip install dist/fuzzyq-*.whl            # anywhere: no cargo needed
#
#   ./scripts/build-wheels.sh --tests OUT    # scripts/test.sh: the same package for this host
#
# `--tests` builds the wheel from `cargo test`'s build instead (the dev profile, which the test
# profile inherits: optimised, with debug assertions; this host's linker; a `linux_x86_64`
# tag): every crate below the extension module is already compiled there, so CI builds the
# workspace once, not twice (BENCHMARKS.md, "CI on two cores").
set -euo pipefail
cd "$(dirname "$0")/.."

build=(--release --zig --compatibility manylinux2014)
if [ "${1:-}" = --tests ]; then
    build=(--profile dev --compatibility linux)
    shift
fi
out=${1:-dist}
venv=target/wheel-build-venv
python=${PYTHON:-python3}
if [ ! -x "$venv/bin/maturin" ]; then
    "$python" -m venv "$venv"
    "$venv/bin/pip" install --quiet --upgrade pip
    "$venv/bin/pip" install --quiet "maturin>=1.5,<2" "ziglang>=0.11,<0.14"
fi
rm -f "$out"/fuzzyq-*.whl
# maturin finds zig as `python3 -m ziglang`: the build environment's Python first on PATH.
PATH="$PWD/$venv/bin:$PATH" "$venv/bin/maturin" build "${build[@]}" --locked --quiet --out "$out"
wheel=$(ls "$out"/fuzzyq-*.whl)
echo "built $wheel ($(du -h "$wheel" | cut -f1))"
