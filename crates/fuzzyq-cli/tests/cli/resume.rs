//! Resumable training: a run continued from any of its checkpoints writes the uninterrupted
//! run's policy byte for byte, for fuzzy Q-iteration (synchronous, extrapolated, modified
//! policy iteration, asynchronous) and for the learners from samples (fuzzy Q-learning,
//! VQQL); a run killed (SIGKILL) or stopped (SIGINT) continues from its last checkpoint; bad
//! checkpoints and resumes fail on one line.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use super::{assert_all_fail, fuzzyq, one_agent_config, stderr};

/// Trains with `args` into `out`, asserting success.
#[track_caller]
fn train(d: &Path, args: &[&str], out: &str) -> Vec<u8> {
    let mut all = vec!["train", "--quiet", "--out", out];
    all.extend_from_slice(args);
    let o = fuzzyq(&all, d);
    assert!(o.status.success(), "{all:?}: {}", stderr(&o));
    std::fs::read(d.join(out)).unwrap()
}

/// For every `every`: a run checkpointing every `every` steps leaves the state of its last
/// multiple of `every` before the end; continuing from it must give the same bytes.
#[track_caller]
fn assert_every_checkpoint_resumes(d: &Path, args: &[&str], everies: &[usize]) {
    let whole = train(d, args, "whole.fzq");
    for &every in everies {
        let every = every.to_string();
        let mut with = args.to_vec();
        with.extend_from_slice(&["--checkpoint", "c.ckpt", "--checkpoint-every", &every]);
        assert_eq!(train(d, &with, "again.fzq"), whole, "{with:?}");
        let mut resumed = args.to_vec();
        resumed.extend_from_slice(&["--resume", "c.ckpt", "--checkpoint", "c.ckpt"]);
        assert_eq!(
            train(d, &resumed, "resumed.fzq"),
            whole,
            "{args:?} resumed from its checkpoint every {every}"
        );
    }
}

#[test]
fn fuzzy_q_iteration_resumes_bit_identically_in_every_scheme() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    for scheme in [
        &["--no-extrapolate", "--evaluation-sweeps", "0"][..],
        &["--extrapolate", "--evaluation-sweeps", "0"],
        &["--extrapolate", "--evaluation-sweeps", "5"],
        &["--async"],
        &["--precision", "f64", "--max-sweeps", "9"],
    ] {
        let mut args = vec!["--config", "one.toml"];
        args.extend_from_slice(scheme);
        assert_every_checkpoint_resumes(d, &args, &[1, 3, 7]);
    }
}

#[test]
fn learners_from_samples_resume_bit_identically() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    for learner in [
        &["--learner", "fql"][..],
        &["--learner", "vqql", "--cells", "16"],
    ] {
        let mut args = vec!["--config", "one.toml", "--episodes", "40", "--seed", "5"];
        args.extend_from_slice(learner);
        assert_every_checkpoint_resumes(d, &args, &[1, 13]);
    }
}

/// Starts `fuzzyq train` with `args`, waits for the checkpoint `c.ckpt` to appear, sends
/// `signal`, and returns the run's exit code and stderr.
fn interrupt(d: &Path, args: &[&str], signal: &str) -> (Option<i32>, String) {
    let _ = std::fs::remove_file(d.join("c.ckpt"));
    let child = Command::new(env!("CARGO_BIN_EXE_fuzzyq"))
        .args(["train", "--quiet"])
        .args(args)
        .current_dir(d)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let start = Instant::now();
    while !d.join("c.ckpt").exists() && start.elapsed() < Duration::from_secs(120) {
        std::thread::sleep(Duration::from_millis(5));
    }
    let pid = child.id().to_string();
    let _ = Command::new("kill").args([signal, &pid]).status();
    let o = child.wait_with_output().unwrap();
    (
        o.status.code(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn killed_and_stopped_runs_continue_from_their_last_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // Two agents on a coarse grid (194,481 cores): about a hundred plain sweeps of a few
    // milliseconds each, long enough to be stopped in the middle.
    let text = std::fs::read_to_string(one_agent_config(d)).unwrap();
    let two = text
        .replace("agents = 1 ", "agents = 2 ")
        .replace(
            "position_cores = [-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0]",
            "position_cores = [-6.0, -3.0, -0.3, 0.0, 0.3, 3.0, 6.0]",
        )
        .replace(
            "velocity_cores = [-3.0, -1.0, 0.0, 1.0, 3.0]",
            "velocity_cores = [-3.0, 0.0, 3.0]",
        );
    assert!(two.contains("velocity_cores = [-3.0, 0.0, 3.0]"));
    std::fs::write(d.join("two.toml"), two).unwrap();
    let args = [
        "--config",
        "two.toml",
        "--no-extrapolate",
        "--evaluation-sweeps",
        "0",
    ];
    let whole = train(d, &args, "whole.fzq");
    let mut with = args.to_vec();
    with.extend_from_slice(&[
        "--checkpoint",
        "c.ckpt",
        "--checkpoint-every",
        "1",
        "--out",
        "p.fzq",
    ]);
    for signal in ["-KILL", "-INT"] {
        let (code, err) = interrupt(d, &with, signal);
        if signal == "-INT" && code == Some(130) {
            // Stopped between two sweeps: the message names the checkpoint to resume from.
            assert!(err.contains("--resume c.ckpt"), "{err}");
            assert_eq!(err.lines().count(), 1, "{err}");
        }
        assert!(
            !d.join("p.fzq").exists(),
            "{signal}: no policy from a stopped run"
        );
        let mut resumed = args.to_vec();
        resumed.extend_from_slice(&["--resume", "c.ckpt", "--checkpoint", "c.ckpt"]);
        assert_eq!(train(d, &resumed, "resumed.fzq"), whole, "after {signal}");
        std::fs::remove_file(d.join("c.ckpt")).unwrap();
        std::fs::remove_file(d.join("resumed.fzq")).unwrap();
    }
}

#[test]
fn bad_checkpoints_and_resumes_fail_on_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    let args = [
        "--config",
        "one.toml",
        "--checkpoint",
        "c.ckpt",
        "--checkpoint-every",
        "2",
    ];
    train(d, &args, "p.fzq");
    train(
        d,
        &[
            "--config",
            "one.toml",
            "--learner",
            "fql",
            "--episodes",
            "20",
            "--checkpoint",
            "f.ckpt",
            "--checkpoint-every",
            "5",
        ],
        "q.fzq",
    );
    let bytes = std::fs::read(d.join("c.ckpt")).unwrap();
    std::fs::write(d.join("short.ckpt"), &bytes[..bytes.len() / 2]).unwrap();
    let mut flipped = bytes.clone();
    let last = flipped.len() - 1;
    flipped[last] ^= 0x40;
    std::fs::write(d.join("flipped.ckpt"), &flipped).unwrap();
    let mut version = bytes.clone();
    version[8] = 9;
    std::fs::write(d.join("version.ckpt"), &version).unwrap();
    let mut longer = bytes;
    longer.extend_from_slice(b"tail");
    std::fs::write(d.join("longer.ckpt"), &longer).unwrap();
    std::fs::write(d.join("text.ckpt"), "gamma = 0.9\n").unwrap();
    std::fs::write(d.join("empty.ckpt"), "").unwrap();
    assert_all_fail(
        d,
        &[
            (
                "train --config one.toml --out o.fzq --resume nothere.ckpt",
                "cannot read checkpoint nothere.ckpt",
            ),
            (
                "train --config one.toml --out o.fzq --resume short.ckpt",
                "truncated",
            ),
            (
                "train --config one.toml --out o.fzq --resume flipped.ckpt",
                "checksum",
            ),
            (
                "train --config one.toml --out o.fzq --resume version.ckpt",
                "format version 9",
            ),
            (
                "train --config one.toml --out o.fzq --resume longer.ckpt",
                "bytes after its content",
            ),
            (
                "train --config one.toml --out o.fzq --resume text.ckpt",
                "not a fuzzyq checkpoint",
            ),
            (
                "train --config one.toml --out o.fzq --resume empty.ckpt",
                "not a fuzzyq checkpoint",
            ),
            (
                "train --config one.toml --out o.fzq --resume p.fzq",
                "(it is a policy file)",
            ),
            (
                "train --config one.toml --out o.fzq --resume .",
                "cannot read checkpoint",
            ),
            (
                "train --config one.toml --out o.fzq --gamma 0.9 --resume c.ckpt",
                "gamma = 0.9",
            ),
            (
                "train --config one.toml --out o.fzq --async --resume c.ckpt",
                "other settings",
            ),
            ("train --out o.fzq --resume c.ckpt", "other settings"),
            (
                "train --config one.toml --out o.fzq --learner fql --episodes 20 --resume c.ckpt",
                "continues fuzzy Q-iteration",
            ),
            (
                "train --config one.toml --out o.fzq --resume f.ckpt",
                "continues a learner from samples",
            ),
            (
                "train --config one.toml --out o.fzq --learner fql --episodes 21 --resume f.ckpt",
                "episodes: 21",
            ),
            (
                "train --config one.toml --out o.fzq --learner vqql --episodes 20 --resume f.ckpt",
                "other settings",
            ),
            (
                "train --config one.toml --out o.fzq --checkpoint c2.ckpt --checkpoint-every 0",
                "--checkpoint-every must be at least 1",
            ),
            (
                "train --config one.toml --out o.fzq --checkpoint-every 3",
                "--checkpoint",
            ),
            (
                "train --config one.toml --out o.fzq --checkpoint o.fzq",
                "--checkpoint",
            ),
            (
                "train --config one.toml --out o.fzq --checkpoint one.toml",
                "--checkpoint",
            ),
            (
                "train --config one.toml --out o.fzq --json c.ckpt --resume c.ckpt",
                "--resume",
            ),
            (
                "train --config one.toml --out o.fzq --learner learned-model --samples 100 --checkpoint c3.ckpt",
                "applies to --learner fqi, fql and vqql",
            ),
            (
                "train --config one.toml --out o.fzq --learner learned-model --samples 100 --resume c.ckpt",
                "applies to --learner fqi, fql and vqql",
            ),
            (
                "train --config one.toml --out o.fzq --operator q-values --checkpoint c3.ckpt",
                "needs --operator values",
            ),
            (
                "train --config one.toml --out o.fzq --checkpoint nodir/c.ckpt",
                "--checkpoint",
            ),
        ],
    );
}
