//! Values the default single-precision solver cannot hold, counts that make no sense, settings
//! that do not apply and endless input are refused up front with one line naming the setting
//! (they used to panic, write NaN tables, be silently ignored or read until memory ran out).

use super::{assert_all_fail, fuzzyq, one_agent_config};

#[test]
fn values_beyond_single_precision_and_empty_counts_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    let text = std::fs::read_to_string(d.join("one.toml")).unwrap();
    let variant = |name: &str, from: &str, to: &str| {
        assert!(text.contains(from), "{from}");
        std::fs::write(d.join(name), text.replacen(from, to, 1)).unwrap();
    };
    variant(
        "force.toml",
        "force_levels = [-2.0, -0.2, 0.0, 0.2, 2.0]",
        "force_levels = [-1e39, 0.0, 1e39]",
    );
    variant("reward.toml", "goal_reward = 5.0", "goal_reward = 1e39");
    variant(
        "cores.toml",
        "position_cores = [-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0]",
        "position_cores = [-1e39, 0.0, 1e39]",
    );
    let o = fuzzyq(&["config", "--env", "khepera"], d);
    let k = String::from_utf8(o.stdout).unwrap();
    assert!(k.contains("max_wheel_speed = 0.8 "), "{k}");
    let k = k.replacen("max_wheel_speed = 0.8 ", "max_wheel_speed = 1e39 ", 1);
    std::fs::write(d.join("khepera.toml"), k).unwrap();
    for env in ["dcmotor", "pendulum", "carhill", "arm"] {
        let o = fuzzyq(&["config", "--env", env], d);
        let t = String::from_utf8(o.stdout).unwrap();
        let line = t.lines().find(|l| l.starts_with("actions = ")).unwrap();
        let big = t.replacen(line, "actions = [-1e39, 0.0, 1e39]", 1);
        std::fs::write(d.join(format!("{env}.toml")), big).unwrap();
    }
    assert_all_fail(
        d,
        &[
            (
                "train --config force.toml --out p.fzq",
                "env.force_levels: must be finite numbers within single precision",
            ),
            (
                "compare --config force.toml --out cmp",
                "env.force_levels: must be finite numbers within single precision",
            ),
            (
                "train --config reward.toml --out p.fzq",
                "env.goal_reward: must be finite numbers within single precision",
            ),
            (
                "train --config cores.toml --out p.fzq",
                "grid.position_cores: must be finite numbers within single precision",
            ),
            (
                "train --env dcmotor --config dcmotor.toml --out p.fzq",
                "env.actions: must be finite numbers within single precision",
            ),
            (
                "train --env pendulum --config pendulum.toml --out p.fzq",
                "env.actions",
            ),
            (
                "train --env carhill --config carhill.toml --out p.fzq",
                "env.actions",
            ),
            (
                "train --env arm --config arm.toml --out p.fzq",
                "env.actions",
            ),
            (
                "train --env khepera --config khepera.toml --out p.fzq",
                "env.max_wheel_speed: must be finite numbers within single precision",
            ),
            (
                "compare --config one.toml --x0=-4,5,0,0 --starts 0 --out cmp",
                "starts: must be at least 1",
            ),
            (
                "train --config one.toml --threads 100000 --out p.fzq",
                "--threads: expected 1 to",
            ),
            (
                "bench --config one.toml --threads 100000",
                "--threads: expected 1 to",
            ),
            // A kernel only the block backup has.
            (
                "train --config one.toml --backup generic --kernel scalar --out p.fzq",
                "solver.kernel: applies to the block backup",
            ),
            (
                "train --config one.toml --operator q-values --kernel scalar --out p.fzq",
                "solver.kernel: applies to the block backup",
            ),
            // Endless input is refused after a bounded read, not read until memory runs out.
            ("rollout --policy /dev/zero", "longer than 16 MiB"),
            (
                "train --config /dev/zero --out p.fzq",
                "line 1 is longer than 1 MiB",
            ),
            (
                "train --env khepera --arena /dev/zero --out p.fzq",
                "line 1 is longer than 1 MiB",
            ),
            (
                "train --config one.toml --learner learned-model --transitions /dev/zero --out p.fzq",
                "line 1 is longer than 1 MiB",
            ),
        ],
    );
}

/// An operating-system error is said once, not once per layer of the error chain.
#[test]
fn os_errors_are_printed_once() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for line in [
        "rollout --policy missing.fzq",
        "train --config missing.toml --out p.fzq",
    ] {
        let o = fuzzyq(&line.split_whitespace().collect::<Vec<_>>(), d);
        let err = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(o.status.code(), Some(2), "{line}: {err}");
        assert_eq!(err.matches("No such file").count(), 1, "{line}: {err}");
    }
}

#[test]
fn runs_beyond_the_memory_limit_and_flags_that_do_not_apply_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    let o = fuzzyq(
        &["train", "--config", "one.toml", "--out", "p.fzq", "--quiet"],
        d,
    );
    assert!(o.status.success());
    let text = std::fs::read_to_string(d.join("one.toml")).unwrap();
    // 161^4 cores x 3 agents' 25 actions: 6.7e8 cores, tens of GB.
    let many: Vec<String> = (0..161)
        .map(|i| format!("{:.1}", -8.0 + 0.1 * i as f64))
        .collect();
    let huge = text
        .replacen(
            "position_cores = [-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0]",
            &format!("position_cores = [{}]", many.join(", ")),
            1,
        )
        .replacen(
            "velocity_cores = [",
            &format!("velocity_cores = [{}] #", many.join(", ")),
            1,
        );
    std::fs::write(d.join("huge.toml"), huge).unwrap();
    // The paper's grid for three agents: 45^6 = 8.3e9 cores, beyond 2^32 (a grid may have
    // more), refused by its memory.
    let three = text.replace("agents = 1 ", "agents = 3 ");
    assert_ne!(three, text);
    std::fs::write(d.join("three.toml"), three).unwrap();
    assert_all_fail(
        d,
        &[
            (
                "train --config three.toml --out h.fzq",
                "GB of memory for 8.304e9 cores",
            ),
            (
                "train --config three.toml --out h.fzq --device gpu --max-memory 100",
                "8.304e9 cores (V on the GPU; the rewards and the result here)",
            ),
            (
                "bench --config huge.toml --max-memory 10",
                "GB of memory for 6.719e8 cores",
            ),
            (
                "bench --config three.toml --device gpu --max-memory 100",
                "8.304e9 cores (V on the GPU; the rewards and V read back here)",
            ),
            (
                "bench --config one.toml --max-memory 0",
                "--max-memory must be a positive",
            ),
        ],
    );
    assert_all_fail(
        d,
        &[
            (
                "train --config huge.toml --out h.fzq",
                "GB of memory for 6.719e8 cores",
            ),
            (
                "train --config huge.toml --out h.fzq",
                "--max-memory GB raises the limit",
            ),
            (
                "train --config one.toml --out h.fzq --operator q-values --max-memory 0.000001",
                "Q-values",
            ),
            (
                "train --config one.toml --out h.fzq --max-memory 0",
                "--max-memory must be a positive",
            ),
            (
                "train --config one.toml --out h.fzq --max-memory nan",
                "--max-memory must be a positive",
            ),
            (
                "train --config one.toml --out h.fzq --max-memory -3",
                "--max-memory",
            ),
            (
                "compare --config huge.toml --out cmp --x0 -4,5,0,0 --learners fqi",
                "GB of memory",
            ),
            (
                "compare --config one.toml --out cmp --x0 -4,5,0,0 --starts 1000000000000",
                "1.000e12 runs",
            ),
            (
                "rollout --policy p.fzq --steps 4294967296",
                "GB of memory for a run of 4.295e9 steps",
            ),
            (
                "rollout --policy p.fzq --starts 1000000000000",
                "GB of memory for 1.000e12 runs",
            ),
            (
                "rollout --policy p.fzq --steps 100000 --max-memory 0.001",
                "more than the limit of 0.00 GB (as set)",
            ),
            (
                "train --config one.toml --out h.fzq --learner fql --operator values",
                "--operator sets the solver",
            ),
            (
                "train --config one.toml --out h.fzq --learner fql --backup block",
                "--backup sets the solver",
            ),
            (
                "train --config one.toml --out h.fzq --learner vqql --xi 0.1",
                "--xi sets the solver",
            ),
            (
                "train --config one.toml --out h.fzq --learner fql --async",
                "--async sets the solver",
            ),
            (
                "train --config one.toml --out h.fzq --learner fql --precision f64",
                "--precision sets the solver",
            ),
            (
                "train --config one.toml --out h.fzq --learner fql --max-sweeps 3",
                "--max-sweeps sets the solver",
            ),
            (
                "train --config one.toml --out h.fzq --learner fql --no-extrapolate",
                "--no-extrapolate sets the solver",
            ),
            (
                "train --config one.toml --out h.fzq --operator q-values --backup generic",
                "--backup does not apply to --operator q-values",
            ),
            (
                "train --config one.toml --out h.fzq --operator q-values --async",
                "runs synchronous sweeps",
            ),
            (
                "train --config one.toml --out h.fzq --operator q-values --evaluation-sweeps 3",
                "--evaluation-sweeps does not apply",
            ),
            (
                "rollout --policy p.fzq --maps m.bmp",
                "--maps m.bmp: the file name must end in .png or .svg",
            ),
            ("rollout --policy p.fzq --plot m.gif", "--plot m.gif"),
        ],
    );
}

#[test]
fn a_fifo_nobody_writes_to_is_refused_after_a_wait() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let made = std::process::Command::new("mkfifo")
        .arg(d.join("fifo.toml"))
        .status();
    if !made.is_ok_and(|s| s.success()) {
        eprintln!("skipped: mkfifo is not available");
        return;
    }
    let o = fuzzyq(&["train", "--config", "fifo.toml", "--out", "p.fzq"], d);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(
        err.contains("cannot read config fifo.toml: a FIFO that no process opened for writing"),
        "{err}"
    );
    assert!(!d.join("p.fzq").exists());
}
