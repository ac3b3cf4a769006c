#!/usr/bin/env bash
# Runs every test of fuzzyq: the check that modules form layers without cycles; Rust unit,
# property, integration and CLI end-to-end tests and doctests; the proof that fuzzyq-core
# builds without std and without an allocator; and the Python package's tests (pytest,
# hypothesis, the Gymnasium and PettingZoo checkers, stubtest) against a wheel built from this
# checkout and installed into a fresh virtual environment.
set -euo pipefail
cd "$(dirname "$0")/.."

python3 scripts/check-layers.py   # layers without cycles (docs/design.md, "Layers")
cargo test --workspace --locked
cargo build --release --locked \
    --manifest-path ci/nostd-check/Cargo.toml --target-dir target/nostd-check

venv=target/python-test-venv
rm -rf "$venv"
./scripts/setup-python.sh "$venv"
"$venv/bin/pip" install --quiet pytest hypothesis mypy gymnasium pettingzoo matplotlib
# Run from outside the source tree so that `import fuzzyq` finds the installed wheel; the
# Python-CLI tests use the binary `cargo test` just built from this checkout.
export FUZZYQ_BIN="$PWD/target/debug/fuzzyq"
(cd target && "$OLDPWD/$venv/bin/python" -m pytest "$OLDPWD/python/tests" -q -p no:cacheprovider)
(cd target && "$OLDPWD/$venv/bin/python" -m mypy.stubtest fuzzyq._fuzzyq)
echo "all tests passed"
