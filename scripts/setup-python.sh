#!/usr/bin/env bash
# Creates the virtual environment `.venv` (or the one given) and installs the fuzzyq Python
# package into it, built from this checkout by scripts/build-wheels.sh (release build, the
# manylinux2014 abi3 wheel for CPython 3.11+, into target/wheels, with the `fuzzyq` command).
#
#   ./scripts/setup-python.sh [VENV [WHEEL]]   # WHEEL: install that wheel, built already
set -euo pipefail
cd "$(dirname "$0")/.."

venv=${1:-.venv}
wheel=${2:-}
python=${PYTHON:-python3}
"$python" -m venv "$venv"
"$venv/bin/pip" install --quiet --upgrade pip
if [ -z "$wheel" ]; then
    rm -rf target/wheels
    ./scripts/build-wheels.sh target/wheels
    wheel=$(ls target/wheels/fuzzyq-*.whl)
fi
"$venv/bin/pip" install --quiet --force-reinstall "$wheel"
"$venv/bin/python" -c "import fuzzyq; print('fuzzyq', fuzzyq.__version__, 'installed in $venv')"
