#!/usr/bin/env bash
# Creates the virtual environment `.venv` (or the one given) and installs the fuzzyq Python
# package into it, built from this checkout (release build, abi3 wheel for CPython 3.11+).
set -euo pipefail
cd "$(dirname "$0")/.."

venv=${1:-.venv}
python=${PYTHON:-python3}
"$python" -m venv "$venv"
"$venv/bin/pip" install --quiet --upgrade pip
"$venv/bin/pip" install --quiet "maturin>=1.5,<2"
rm -rf target/wheels
"$venv/bin/maturin" build --release --locked --quiet --out target/wheels
"$venv/bin/pip" install --quiet --force-reinstall target/wheels/fuzzyq-*.whl
"$venv/bin/python" -c "import fuzzyq; print('fuzzyq', fuzzyq.__version__, 'installed in $venv')"
