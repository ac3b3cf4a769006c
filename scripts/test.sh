#!/usr/bin/env bash
# Runs every test of fuzzyq: unit, property, integration and CLI end-to-end tests, doctests,
# and the proof that fuzzyq-core builds without std and without an allocator.
set -euo pipefail
cd "$(dirname "$0")/.."

cargo test --workspace --locked
cargo build --release --locked \
    --manifest-path ci/nostd-check/Cargo.toml --target-dir target/nostd-check
echo "all tests passed"
