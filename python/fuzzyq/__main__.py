"""The ``fuzzyq`` command line, as the wheel installs it: ``fuzzyq ...`` or
``python -m fuzzyq ...`` run the Rust binary's own code (train, rollout, compare, config,
export, bench), compiled into the extension module, with no Rust toolchain needed."""

from __future__ import annotations

import sys

from fuzzyq._fuzzyq import _cli


def main() -> None:
    """Runs the command line on ``sys.argv`` and exits with its code."""
    sys.exit(_cli(["fuzzyq", *sys.argv[1:]]))


if __name__ == "__main__":
    main()
