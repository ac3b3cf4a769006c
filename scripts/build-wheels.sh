#!/usr/bin/env bash
# Builds the fuzzyq wheel that installs in seconds with no Rust toolchain: one abi3 wheel
# (CPython 3.11 and newer) for manylinux2014 (glibc 2.17 or newer) on this machine's
# architecture, carrying the Python package, the extension and the `fuzzyq` command line
# (`fuzzyq ...` and `python -m fuzzyq ...` after `pip install`). Zig, from PyPI's `ziglang`,
# links against the old glibc, so any Linux host with a Rust toolchain builds it.
#
#   ./scripts/build-wheels.sh [OUT_DIR]      # default: dist/
#   pip install dist/fuzzyq-*.whl            # anywhere: no cargo needed
set -euo pipefail
cd "$(dirname "$0")/.."

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
PATH="$PWD/$venv/bin:$PATH" "$venv/bin/maturin" build --release --locked --quiet --zig --compatibility manylinux2014 \
    --out "$out"
wheel=$(ls "$out"/fuzzyq-*.whl)
echo "built $wheel ($(du -h "$wheel" | cut -f1))"
