"""``python -m fuzzyq.distributed train --config FILE.toml --out POLICY.fzq [--address ADDRESS]
[--json SUMMARY.json]``: ``fuzzyq train --config FILE.toml`` with the sweeps on Ray.

Exit codes: 0 done, 2 bad input (a one-line error naming it), 130 interrupted (Ctrl-C; with
``--checkpoint`` the run continues with ``--resume``), 1 anything else.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path
from typing import Any

import fuzzyq


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="python -m fuzzyq.distributed",
        description="Fuzzy Q-iteration with the sweeps distributed on a Ray cluster: the "
        "policy file of `fuzzyq train --config FILE.toml`, byte for byte.",
    )
    sub = p.add_subparsers(dest="command", required=True)
    t = sub.add_parser(
        "train",
        help="train a configuration (fuzzy Q-iteration) on Ray",
        description="Train a configuration (as `fuzzyq config` writes it) with every sweep "
        "computed by Ray tasks, one per group of slabs, each fetching only its halo of V.",
    )
    t.add_argument("--config", required=True, metavar="FILE.toml", help="the configuration")
    t.add_argument("--out", required=True, metavar="POLICY.fzq", help="the policy file to write")
    t.add_argument(
        "--address",
        metavar="ADDRESS",
        help='a running Ray cluster ("auto", "HOST:PORT" or "ray://HOST:PORT"); '
        "default: a new local Ray instance",
    )
    t.add_argument("--json", metavar="SUMMARY.json", help="also write a JSON summary of the run")
    t.add_argument(
        "--slabs-per-task",
        type=int,
        metavar="N",
        help="slabs per task and per object of V (default: about four tasks per CPU)",
    )
    t.add_argument(
        "--checkpoint",
        metavar="FILE",
        help="write the run's state to FILE after every sweep (the format of `fuzzyq train "
        "--checkpoint`)",
    )
    t.add_argument(
        "--resume", metavar="FILE", help="continue the run whose state --checkpoint wrote"
    )
    t.add_argument("--quiet", action="store_true", help="no progress lines")
    return p


def _fail(message: str, code: int = 2) -> int:
    print(f"error: {message}", file=sys.stderr)
    return code


def _write_json(path: Path, data: dict[str, Any]) -> None:
    """Writes `data` atomically (a temporary file beside `path`, then a rename)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as f:
            json.dump(data, f, indent=2)
            f.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _progress(record: dict[str, Any]) -> None:
    kind = "evaluation" if record["evaluation"] else "full backup"
    print(
        f"sweep {record['sweep']:>4} ({kind}): delta {record['delta']:.4g}, "
        f"{record['seconds']:.1f} s",
        file=sys.stderr,
        flush=True,
    )


def main(argv: list[str] | None = None) -> int:
    args = _parser().parse_args(argv)
    from fuzzyq import distributed

    config_path = Path(args.config)
    try:
        config = config_path.read_text()
    except (OSError, UnicodeDecodeError) as e:
        return _fail(f"--config {config_path}: cannot read it ({e})")
    if args.slabs_per_task is not None and args.slabs_per_task < 1:
        return _fail(f"--slabs-per-task {args.slabs_per_task}: must be at least 1")
    for flag, value in (
        ("--out", args.out),
        ("--json", args.json),
        ("--checkpoint", args.checkpoint),
    ):
        if value is not None and not Path(value).resolve().parent.is_dir():
            return _fail(f"{flag} {value}: its folder does not exist")
    if args.resume is not None and not Path(args.resume).is_file():
        return _fail(f"--resume {args.resume}: no such file")
    try:
        run = distributed.train(
            config,
            out=args.out,
            address=args.address,
            slabs_per_group=args.slabs_per_task,
            checkpoint=args.checkpoint,
            resume=args.resume,
            on_sweep=None if args.quiet else _progress,
        )
    except KeyboardInterrupt:
        hint = f"; continue with --resume {args.checkpoint}" if args.checkpoint else ""
        print(f"interrupted{hint}", file=sys.stderr)
        return 130
    except distributed.RayUnavailableError as e:
        return _fail(str(e))
    except fuzzyq.ConfigError as e:
        return _fail(f"--config {config_path}: {e}")
    except (fuzzyq.InputError, fuzzyq.InputTypeError, fuzzyq.PolicyFileError) as e:
        return _fail(str(e))
    except fuzzyq.FuzzyqError as e:
        return _fail(str(e), 1)
    summary = run.summary()
    if args.json is not None:
        _write_json(Path(args.json), summary)
    if not args.quiet:
        d = summary["distributed"]
        print(
            f"wrote {args.out}: {summary['sweeps']} sweeps, converged {summary['converged']}, "
            f"error bound {summary['error_bound']:.4g}; {d['groups']} tasks per pass on "
            f"{d['nodes']} node(s), {d['cpus']:g} CPUs; halos fetched "
            f"{100 * run.fetched_fraction:.1f}% of a full broadcast of V; {d['seconds']:.1f} s",
            file=sys.stderr,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
