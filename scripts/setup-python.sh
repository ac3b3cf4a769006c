#!/usr/bin/env bash
# Creates the virtual environment `.venv` (or the one given) and installs the fuzzyq Python
# package into it, built from this checkout by scripts/build-wheels.sh (release build, the
# manylinux2014 abi3 wheel for CPython 3.11+, into target/wheels, with the `fuzzyq` command).
set -euo pipefail
cd "$(dirname "$0")/.."

venv=${1:-.venv}
python=${PYTHON:-python3}
"$python" -m venv "$venv"
"$venv/bin/pip" install --quiet --upgrade pip
rm -rf target/wheels
./scripts/build-wheels.sh target/wheels
"$venv/bin/pip" install --quiet --force-reinstall target/wheels/fuzzyq-*.whl
"$venv/bin/python" -c "import fuzzyq; print('fuzzyq', fuzzyq.__version__, 'installed in $venv')"
