#!/usr/bin/env bash
# Runs every test of fuzzyq: the check that modules form layers without cycles; Rust unit,
# property, integration and CLI end-to-end tests and doctests; the proof that fuzzyq-core and
# the example robot controller build without std and without an allocator; and the Python
# package's tests (pytest, hypothesis, the Gymnasium and PettingZoo checkers, stubtest) against
# a wheel built from this checkout and installed into a fresh virtual environment.
# Also: mypy --strict on the README's examples, the package's doctests, and the strict build of
# the documentation site (mkdocs.yml).
set -euo pipefail
cd "$(dirname "$0")/.."

python3 scripts/check-layers.py   # layers without cycles (docs/design.md, "Layers")
# fuzzyq-core's unit tests (`test = false` in its manifest: they compile the kernels once more)
# build in a target directory of their own (profile `core-unit`: opt-level 1), started now at
# the lowest CPU priority: on two cores they take what the steps after the workspace's build
# leave idle (the wheel's build, the Python tests), not the build's time. They run last.
# A process group of their own (`set -m`), to be stopped as one, but not a session of their
# own: Linux schedules each session's processes as one group (autogroups) beside the others,
# which would give them half the CPU whatever their niceness.
mkdir -p target
core_log=target/core-unit-build.log
core_unit=(cargo test -p fuzzyq-core --features parallel,serde --lib --profile core-unit --locked)
set -m
CARGO_TARGET_DIR=target/core-unit nice -n 19 "${core_unit[@]}" --no-run > "$core_log" 2>&1 &
core_pid=$!
set +m
trap 'kill -- -"$core_pid" 2>/dev/null || kill "$core_pid" 2>/dev/null || true' EXIT
cargo test --workspace --locked
# fuzzyq-core alone with the standard library and serde, as a dependent that asks for both
# builds it (inside the workspace other crates' features hide a missing one).
cargo check -p fuzzyq-core --features parallel,serde --locked
cargo build --release --locked \
    --manifest-path ci/nostd-check/Cargo.toml --target-dir target/nostd-check
# The example robot controller as firmware: `no_std`, no allocator, its own panic handler, a
# static library exporting its C entry point (examples/embedded-controller).
cargo rustc --locked -p fuzzyq-embedded-controller --lib --profile firmware \
    --features firmware --crate-type staticlib

# The Python package's wheel from the build above (the dev profile, which the test profile
# is): only the extension module is compiled again, where every crate below it has the
# features it has in the workspace's build (fuzzyq-py's manifest asks for those the workspace
# adds). A crate that differs would be compiled again, with all above it: said and refused.
# The release wheel (scripts/build-wheels.sh without `--tests`: release profile, zig,
# manylinux2014) is the same package built with other flags; building it here too compiled the
# workspace a second time (BENCHMARKS.md, "CI on two cores").
features() {
    cargo tree --locked -q -e features -f '{p} {f}' --prefix none "$@" \
        | grep -v ' feature ' | sed 's/ (\*)$//' | sort -u
}
features --workspace -e normal,build,dev > target/features-workspace.txt
features -p fuzzyq-py -e normal,build > target/features-wheel.txt
if differ=$(comm -23 target/features-wheel.txt target/features-workspace.txt | grep .); then
    echo "error: the wheel's crates differ in features from the tests' build (align them in" \
        "crates/fuzzyq-py/Cargo.toml as its comment says): $(echo "$differ" | tr '\n' ';')" >&2
    exit 1
fi
./scripts/build-wheels.sh --tests target/wheels
# The wheel built above (build-wheels.sh leaves only it there): test_wheel.py installs it into
# a fresh environment with no cargo on PATH and runs the package, the `fuzzyq` command and
# `python -m fuzzyq` there.
FUZZYQ_WHEEL=$(ls "$PWD"/target/wheels/fuzzyq-*.whl)
export FUZZYQ_WHEEL
venv=target/python-test-venv
rm -rf "$venv"
./scripts/setup-python.sh "$venv" "$FUZZYQ_WHEEL"
"$venv/bin/pip" install --quiet pytest hypothesis mypy gymnasium pettingzoo matplotlib joblib "ray>=2.9"
# Run from outside the source tree so that `import fuzzyq` finds the installed wheel; the
# Python-CLI tests use the binary `cargo test` just built from this checkout.
export FUZZYQ_BIN="$PWD/target/debug/fuzzyq"
(cd target && "$OLDPWD/$venv/bin/python" -m pytest "$OLDPWD/python/tests" -q -p no:cacheprovider --durations=10)
# (The pytest run above includes `mypy --strict` on every README python block and
# examples/*.py, python/tests/test_readme.py, and the package's doctests, test_docs.py.)
# The documentation site (mkdocs.yml): the pinned tools, then a strict build (any warning fails).
"$venv/bin/pip" install --quiet -r docs/requirements.txt
NO_MKDOCS_2_WARNING=1 "$venv/bin/mkdocs" build --strict --quiet --site-dir target/site
(cd target && "$OLDPWD/$venv/bin/python" -m mypy.stubtest fuzzyq._fuzzyq)
if ! wait "$core_pid"; then
    cat "$core_log"
    echo "error: the build of fuzzyq-core's unit tests failed" >&2
    exit 1
fi
CARGO_TARGET_DIR=target/core-unit "${core_unit[@]}"
echo "all tests passed"
