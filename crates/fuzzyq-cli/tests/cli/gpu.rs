//! `--device gpu`: training and benchmarks on whatever adapter opens (CI's lavapipe; skipped,
//! with a message, where none does), and the GPU path's refusals, each one line and exit code
//! 2 with nothing written.

use std::path::Path;
use std::process::Command;

use super::{assert_all_fail, changed, fuzzyq, json, snapshot, stderr};

/// `--device gpu` where no adapter opens (`FUZZYQ_GPU_ADAPTER` naming none): one line and
/// exit code 2, nothing written, whether the GPU is opened beside the set-up (a small run)
/// or before it (three point masses: a host estimate over 1 GiB).
#[test]
fn training_without_a_gpu_fails_on_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let three =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/three-point-masses.toml");
    let three = three.to_str().unwrap();
    for args in [
        &["--env", "pointmass"][..],
        &["--env", "pointmass", "--quiet"][..],
        &["--config", three][..],
    ] {
        let before = snapshot(d);
        let o = Command::new(env!("CARGO_BIN_EXE_fuzzyq"))
            .arg("train")
            .args(args)
            .args(["--device", "gpu", "--out", "g.fzq"])
            .env("FUZZYQ_GPU_ADAPTER", "no-such-adapter")
            .current_dir(d)
            .output()
            .unwrap();
        let err = stderr(&o);
        let last = err.lines().last().unwrap_or_default();
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(last.starts_with("error: "), "{args:?}: {err}");
        assert!(last.contains("no-such-adapter"), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
        if args.contains(&"--quiet") {
            assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        }
        assert!(changed(&before, &snapshot(d)).is_empty(), "{args:?}");
    }
}

/// A `FUZZYQ_GPU_*` setting its variable does not take (a mistyped kernel name, say): one
/// line naming the variable, its value and what it takes, exit code 2, nothing written, and
/// before any adapter is looked for (so on any machine), instead of a run on the default.
#[test]
fn a_mistyped_gpu_setting_fails_on_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (var, value, takes) in [
        ("FUZZYQ_GPU_LAST", "unroled", "joined"),
        ("FUZZYQ_GPU_STAGES", "merge", "rows, merged or unrolled"),
        ("FUZZYQ_GPU_EVAL", "stages", "auto, nested or stages:K"),
        ("FUZZYQ_GPU_SUBGROUPS", "no", "1 or 0"),
        ("FUZZYQ_GPU_BATCH_MB", "0", "a positive whole number of MiB"),
        (
            "FUZZYQ_GPU_CHECKS",
            "bound",
            "zero, loops, division and bounds",
        ),
    ] {
        let before = snapshot(d);
        let o = Command::new(env!("CARGO_BIN_EXE_fuzzyq"))
            .args(["train", "--env", "dcmotor", "--device", "gpu", "--quiet"])
            .args(["--precision", "f32", "--out", "g.fzq"])
            .env(var, value)
            .env("FUZZYQ_GPU_ADAPTER", "no-such-adapter")
            .current_dir(d)
            .output()
            .unwrap();
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{var}: {err}");
        assert_eq!(err.lines().count(), 1, "{var}: {err}");
        assert!(
            err.starts_with(&format!("error: {var}={value} ")),
            "{var}: {err}"
        );
        assert!(err.contains(takes), "{var}: {err}");
        assert!(changed(&before, &snapshot(d)).is_empty(), "{var}");
    }
}

/// `--device gpu`: a small run on whatever adapter opens (CI's lavapipe; skipped, with a
/// message, where none does), and its refusals as one line each.
#[test]
fn train_on_the_gpu_and_its_refusals() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    assert_all_fail(
        d,
        &[
            (
                "train --env pointmass --device gpu --precision f64 --out x.fzq",
                "solver.device: \"gpu\" runs in f32",
            ),
            (
                "train --env pointmass --device gpu --async --out x.fzq",
                "synchronous sweeps",
            ),
            (
                "bench --device gpu --kernel avx2",
                "--kernel chooses a CPU kernel",
            ),
            ("train --env pointmass --device tpu --out x.fzq", "tpu"),
        ],
    );
    let o = fuzzyq(
        &[
            "train",
            "--env",
            "dcmotor",
            "--precision",
            "f32",
            "--device",
            "gpu",
            "--out",
            "g.fzq",
            "--json",
            "g.json",
            "--quiet",
        ],
        d,
    );
    let err = stderr(&o);
    if err.contains("no GPU adapter") && std::env::var_os("FUZZYQ_REQUIRE_GPU").is_none() {
        eprintln!("skipped: {err}");
        return;
    }
    assert!(o.status.success(), "{err}");
    let j = json(&d.join("g.json"));
    assert_eq!(j["kernel"], "wgpu");
    assert_eq!(j["converged"], true);
    // Opening the GPU is timed apart from the solve (and in quiet runs too); a run this
    // small opens it beside its set-up, so the two overlap.
    let device = j["device_seconds"].as_f64().expect("device_seconds");
    let command = j["command_seconds"].as_f64().unwrap();
    assert_eq!(j["device_beside_setup"], true, "{j}");
    assert!(device > 0.0 && device <= command, "{j}");
    assert!(j["seconds"].as_f64().unwrap() <= command, "{j}");
}

/// `bench --device gpu` on three point masses with a 1 MiB stage budget and `V` in parts of
/// 64 KiB: the passes run in batches below fixed cores of the first blocks, over `V`'s parts,
/// and the report says so.
#[test]
fn bench_on_the_gpu_batches_three_point_masses() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let example =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/three-point-masses.toml");
    let text = std::fs::read_to_string(example).unwrap();
    let (grid, _) = text.split_once("\nposition_cores").unwrap();
    let (_, rest) = text.split_once("\nvelocity_cores").unwrap();
    let (_, rest) = rest.split_once('\n').unwrap();
    // 3 positions x 2 velocities per axis: 6^6 = 46,656 cores.
    let small =
        format!("{grid}\nposition_cores = [-6.0, 0.0, 6.0]\nvelocity_cores = [-1.0, 1.0]\n{rest}");
    std::fs::write(d.join("three.toml"), small).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_fuzzyq"))
        .args([
            "bench",
            "--config",
            "three.toml",
            "--device",
            "gpu",
            "--backups",
            "1",
            "--peak-seconds",
            "0.05",
            "--json",
            "b.json",
        ])
        .env("FUZZYQ_GPU_BATCH_MB", "1")
        // A slab of V takes 6^5 x 4 bytes (31 KB): parts of two slabs.
        .env("FUZZYQ_GPU_PART_KB", "64")
        .current_dir(d)
        .output()
        .unwrap();
    let err = stderr(&o);
    if err.contains("no GPU adapter") && std::env::var_os("FUZZYQ_REQUIRE_GPU").is_none() {
        eprintln!("skipped: {err}");
        return;
    }
    assert!(o.status.success(), "{err}");
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(out.contains("below fixed cores of block"), "{out}");
    assert!(out.contains("; V in 3 parts;"), "{out}");
    let j = json(&d.join("b.json"));
    assert_eq!(j["v_parts"], 3);
    assert_eq!(j["cores"], 6u64.pow(6));
    assert_eq!(j["joint_actions"], 729);
    assert!(j["batch_level"].as_u64().unwrap() >= 1, "{j}");
    assert!(j["batches_per_pass"].as_u64().unwrap() > 1, "{j}");
    assert!(j["run_bytes"].as_u64().unwrap() > 4 * 6u64.pow(6), "{j}");
    // Where the set-up and the device's opening went.
    let (setup, compile) = (j["setup_seconds"].as_f64(), j["compile_seconds"].as_f64());
    assert!(
        matches!((setup, compile), (Some(s), Some(c)) if 0.0 < c && c <= s),
        "{j}"
    );
    let opening = j["opening_seconds"].as_array().unwrap();
    assert_eq!(opening.len(), 3, "{j}");
    assert!(
        opening.iter().all(|x| x.as_f64().is_some_and(|x| x >= 0.0)),
        "{j}"
    );
    assert!(out.contains("(compiling kernels "), "{out}");
}
