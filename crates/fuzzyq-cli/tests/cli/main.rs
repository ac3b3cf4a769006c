//! End-to-end tests of the `fuzzyq` binary: a small train + rollout, and bad input of every
//! kind giving one clear line and exit code 2 without touching existing files.
#![allow(missing_docs)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::SystemTime;

mod deploy;
mod gpu;
mod limits;
mod outputs;
mod reference;
mod resume;

fn fuzzyq(args: &[&str], dir: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_fuzzyq"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run fuzzyq")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// One bad invocation: the command line (split at whitespace, so no argument holds a space)
/// and a fragment of the one-line error it must give.
type BadCase<'a> = (&'a str, &'a str);

/// Runs every case in `dir` and asserts that each one fails cleanly: exit code 2, one
/// `error:` line on stderr containing the case's fragment, and no file or folder under `dir`
/// created, removed or changed (bytes and modification time).
#[track_caller]
fn assert_all_fail(dir: &Path, cases: &[BadCase<'_>]) {
    for &(line, needle) in cases {
        let args: Vec<&str> = line.split_whitespace().collect();
        let before = snapshot(dir);
        let o = fuzzyq(&args, dir);
        let err = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{line}: stderr: {err}");
        assert_eq!(err.lines().count(), 1, "{line}: one line expected: {err}");
        assert!(err.starts_with("error: "), "{line}: {err}");
        assert!(err.contains(needle), "{line}: {needle:?} not in {err:?}");
        let touched = changed(&before, &snapshot(dir));
        assert!(touched.is_empty(), "{line}: touched {touched:?}");
    }
}

/// Every path under a directory, relative to it, with each file's bytes and modification time
/// (`None` for folders).
type Snapshot = BTreeMap<PathBuf, Option<(Vec<u8>, SystemTime)>>;

fn snapshot(dir: &Path) -> Snapshot {
    let mut all = Snapshot::new();
    let mut folders = vec![dir.to_path_buf()];
    while let Some(folder) = folders.pop() {
        for entry in std::fs::read_dir(&folder).unwrap() {
            let path = entry.unwrap().path();
            let meta = std::fs::symlink_metadata(&path).unwrap();
            let key = path.strip_prefix(dir).unwrap().to_path_buf();
            if meta.is_dir() {
                all.insert(key, None);
                folders.push(path);
            } else {
                let bytes = std::fs::read(&path).unwrap();
                all.insert(key, Some((bytes, meta.modified().unwrap())));
            }
        }
    }
    all
}

/// The paths created, removed or changed between two snapshots.
fn changed(before: &Snapshot, after: &Snapshot) -> Vec<PathBuf> {
    let paths: BTreeSet<&PathBuf> = before.keys().chain(after.keys()).collect();
    paths
        .into_iter()
        .filter(|p| before.get(*p) != after.get(*p))
        .cloned()
        .collect()
}

/// The paper's config with one agent: trains in milliseconds.
fn one_agent_config(dir: &Path) -> PathBuf {
    let o = fuzzyq(&["config", "--env", "pointmass"], dir);
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(text.contains("position_cores = [-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0]"));
    let path = dir.join("one.toml");
    std::fs::write(&path, text.replace("agents = 2 ", "agents = 1 ")).unwrap();
    path
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn train_and_rollout_end_to_end() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    let o = fuzzyq(
        &[
            "train",
            "--env",
            "pointmass",
            "--config",
            "one.toml",
            "--out",
            "p.fzq",
            "--json",
            "train.json",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let t = json(&d.join("train.json"));
    for key in [
        "sweeps",
        "converged",
        "delta_inf",
        "seconds",
        "cores",
        "joint_actions",
    ] {
        assert!(t.get(key).is_some(), "summary lacks {key}");
    }
    assert_eq!(t["cores"], 2025);
    assert_eq!(t["joint_actions"], 25);
    assert_eq!(t["converged"], true);
    assert!(t["delta_inf"].as_f64().unwrap() <= 0.05);
    // The closing line counts the kinds of sweeps as the summary does.
    let line = format!(
        "converged after {} sweeps ({} full backups + {} evaluation sweeps) in ",
        t["sweeps"], t["full_backups"], t["evaluation_sweeps"]
    );
    assert!(stderr(&o).contains(&line), "{line:?} in {}", stderr(&o));
    // Before the sweeps, the scheme the solver chose (the default: modified policy iteration).
    let scheme = "modified policy iteration: full backups, each followed by up to 5 evaluation \
                  sweeps under its greedy actions, every sweep extrapolated\n";
    assert!(stderr(&o).contains(scheme), "{scheme:?} in {}", stderr(&o));
    // And a coarse start's sweeps and cores.
    let args = ["train", "--config", "one.toml", "--coarse-start"];
    let o = fuzzyq(
        &[&args[..], &["--out", "c.fzq", "--json", "c.json"]].concat(),
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let c = json(&d.join("c.json"));
    let line = format!(
        "({} full backups + {} evaluation sweeps, after a coarse start: {} sweeps on {} cores in ",
        c["full_backups"],
        c["evaluation_sweeps"],
        c["coarse_start"]["sweeps"],
        c["coarse_start"]["cores"]
    );
    assert!(stderr(&o).contains(&line), "{line:?} in {}", stderr(&o));
    let scheme = format!(
        "every sweep extrapolated, after a coarse start ({} sweeps on {} cores in ",
        c["coarse_start"]["sweeps"], c["coarse_start"]["cores"]
    );
    assert!(stderr(&o).contains(&scheme), "{scheme:?} in {}", stderr(&o));
    // Where the time went: the solver's parts within `seconds`, the writing after it, and the
    // command around both (no GPU: no device time).
    let secs = |k: &str| c[k].as_f64().unwrap_or_else(|| panic!("{k} in {c}"));
    let parts = secs("setup_seconds")
        + c["coarse_start"]["seconds"].as_f64().unwrap()
        + secs("sweep_seconds")
        + secs("result_seconds");
    assert!(parts > 0.0 && parts <= secs("seconds"), "{c}");
    assert!(secs("write_seconds") > 0.0, "{c}");
    assert!(
        secs("seconds") + secs("write_seconds") <= secs("command_seconds"),
        "{c}"
    );
    assert!(c.get("device_seconds").is_none(), "{c}");
    std::fs::remove_file(d.join("c.fzq")).unwrap();
    std::fs::remove_file(d.join("c.json")).unwrap();
    // Extrapolation (the default) needs far fewer sweeps than the paper's plain iteration,
    // which needs 114 (the change decays like 5 * 0.96^k).
    let o = fuzzyq(
        &[
            "train",
            "--config",
            "one.toml",
            "--no-extrapolate",
            "--out",
            "plain.fzq",
            "--json",
            "plain.json",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let scheme = "value iteration: full backups (the paper's fuzzy Q-iteration)\n";
    assert!(stderr(&o).contains(scheme), "{scheme:?} in {}", stderr(&o));
    let plain = json(&d.join("plain.json"));
    assert_eq!(plain["sweeps"], 114);
    assert!(t["sweeps"].as_u64().unwrap() < 50, "{}", t["sweeps"]);
    std::fs::remove_file(d.join("plain.fzq")).unwrap();
    std::fs::remove_file(d.join("plain.json")).unwrap();

    for (kind, plot) in [("greedy", "r.png"), ("interpolated", "r.svg")] {
        let o = fuzzyq(
            &[
                "rollout",
                "--policy",
                "p.fzq",
                "--x0",
                "-4,-6,-2,2",
                "--policy-kind",
                kind,
                "--csv",
                "r.csv",
                "--plot",
                plot,
                "--json",
                "m.json",
            ],
            d,
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let m = json(&d.join("m.json"));
        for key in [
            "reach_step",
            "reach_time_s",
            "arrival_time_s",
            "final_error_m",
            "return",
            "value_x0",
        ] {
            assert!(m.get(key).is_some(), "metrics lack {key}");
        }
        assert!(m["reach_time_s"].as_f64().unwrap() <= 12.0, "{m}");
        assert!(m["final_error_m"][0].as_f64().unwrap() < 0.08, "{m}");
        let csv = std::fs::read_to_string(d.join("r.csv")).unwrap();
        assert_eq!(csv.lines().count(), 1 + 76);
        assert!(csv.starts_with("t,sx1,sy1,vx1,vy1,ux1,uy1,reward\n"));
        let img = std::fs::read(d.join(plot)).unwrap();
        if plot.ends_with(".png") {
            assert_eq!(&img[..8], b"\x89PNG\r\n\x1a\n");
        } else {
            assert!(String::from_utf8_lossy(&img).contains("<svg"));
        }
    }
    // Only the requested files: no temporaries left behind.
    let mut names: Vec<String> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .collect();
    names.sort();
    assert_eq!(
        names,
        [
            "m.json",
            "one.toml",
            "p.fzq",
            "r.csv",
            "r.png",
            "r.svg",
            "train.json"
        ]
    );
}

#[test]
fn bad_input_fails_cleanly_without_touching_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    std::fs::write(d.join("keep.fzq"), b"precious").unwrap();
    let text = std::fs::read_to_string(d.join("one.toml")).unwrap();
    std::fs::write(d.join("bad.toml"), text.replace("mass = 0.5", "mass = -2")).unwrap();
    std::fs::write(d.join("typo.toml"), text.replace("gamma =", "gama =")).unwrap();
    let o = fuzzyq(
        &["train", "--config", "one.toml", "--out", "p.fzq", "-q"],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let bytes = std::fs::read(d.join("p.fzq")).unwrap();
    std::fs::write(d.join("cut.fzq"), &bytes[..bytes.len() / 2]).unwrap();

    assert_all_fail(
        d,
        &[
            // Invalid settings, from flags and from the file.
            (
                "train --gamma 1.5 --out keep.fzq",
                "solver.gamma: must be in [0, 1), got 1.5",
            ),
            (
                "train --config bad.toml --out keep.fzq",
                "env.mass: must be a positive number, got -2",
            ),
            ("train --config typo.toml --out keep.fzq", "gama"),
            (
                "train --config missing.toml --out keep.fzq",
                "cannot read config missing.toml",
            ),
            // An unwritable destination is refused before any training.
            (
                "train --config one.toml --out no/such/dir/p.fzq",
                "does not exist",
            ),
            // Policies that are not policies.
            ("rollout --policy keep.fzq", "is not a fuzzyq policy file"),
            ("rollout --policy nothing.fzq", "cannot read nothing.fzq"),
            ("rollout --policy cut.fzq", "is truncated"),
            // Bad rollout arguments.
            (
                "rollout --policy p.fzq",
                "x0: the policy has 1 agent; give x0 with 4 values",
            ),
            ("rollout --policy p.fzq --x0 1,2,x,4", "--x0: value 3"),
            (
                "rollout --policy p.fzq --x0 1,2,30,4",
                "x0[2] = 30 is outside the state range [-3, 3]",
            ),
            (
                "rollout --policy p.fzq --x0 1,2,0,0 --plot f.jpg",
                "must end in .png or .svg",
            ),
        ],
    );
    assert_eq!(std::fs::read(d.join("keep.fzq")).unwrap(), b"precious");

    // Usage errors exit with 2; help with 0.
    let o = fuzzyq(&["train", "--no-such-flag"], d);
    assert_eq!(o.status.code(), Some(2));
    let o = fuzzyq(&["--help"], d);
    assert_eq!(o.status.code(), Some(0));
    assert!(String::from_utf8_lossy(&o.stdout).contains("rollout"));
}

#[test]
fn khepera_train_rollout_and_starts() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = fuzzyq(&["config", "--env", "khepera"], d);
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    // One robot on the default grid trains in a fraction of a second.
    std::fs::write(
        d.join("one.toml"),
        text.replace("agents = 2 ", "agents = 1 "),
    )
    .unwrap();
    let arena = "x = [-6.0, 6.0]\ny = [-6.0, 6.0]\n[[obstacle]]\nshape = \"disc\"\ncenter = [2.0, 2.0]\nradius = 0.3\n";
    std::fs::write(d.join("arena.toml"), arena).unwrap();
    let o = fuzzyq(
        &[
            "train",
            "--env",
            "khepera",
            "--config",
            "one.toml",
            "--arena",
            "arena.toml",
            "--out",
            "k.fzq",
            "-q",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = fuzzyq(
        &[
            "rollout",
            "--policy",
            "k.fzq",
            "--x0",
            "-3,2,0,0",
            "--headings",
            "90",
            "--steps",
            "200",
            "--json",
            "m.json",
            "--plot",
            "k.png",
            "--csv",
            "k.csv",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let m = json(&d.join("m.json"));
    assert_eq!(m["collisions"]["total"], 0);
    assert_eq!(m["success"], true);
    assert!(m["reach_time_s"].as_f64().is_some());
    assert!(std::fs::metadata(d.join("k.png")).unwrap().len() > 10_000);
    let csv = std::fs::read_to_string(d.join("k.csv")).unwrap();
    assert!(csv.starts_with("t,sx1,sy1,vx1,vy1,vl1,vr1,reward"), "{csv}");
    let o = fuzzyq(
        &[
            "rollout", "--policy", "k.fzq", "--starts", "4", "--seed", "3", "--steps", "300",
            "--json", "s.json", "--plot", "s.png",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let s = json(&d.join("s.json"));
    assert_eq!(s["starts"], 4);
    assert_eq!(s["runs"].as_array().unwrap().len(), 4);
    // Model-free fuzzy Q-learning: policy, curve and summary.
    let o = fuzzyq(
        &[
            "train",
            "--env",
            "khepera",
            "--learner",
            "fql",
            "--episodes",
            "3",
            "--out",
            "f.fzq",
            "--curve",
            "c.csv",
            "--json",
            "f.json",
            "-q",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let f = json(&d.join("f.json"));
    assert_eq!(f["episodes"], 3);
    let curve = std::fs::read_to_string(d.join("c.csv")).unwrap();
    assert_eq!(curve.lines().count(), 4, "{curve}");
    assert!(std::fs::read(d.join("f.fzq")).unwrap().len() > 1000);
    // ... rolled out like a joint policy, from one start or many.
    let o = fuzzyq(
        &[
            "rollout", "--policy", "f.fzq", "--steps", "20", "--json", "fr.json", "--plot",
            "fr.png",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(json(&d.join("fr.json"))["steps"], 20);
    let o = fuzzyq(
        &[
            "rollout", "--policy", "f.fzq", "--starts", "2", "--steps", "20", "--json", "fs.json",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        json(&d.join("fs.json"))["runs"].as_array().unwrap().len(),
        2
    );

    // Bad input: one line, exit code 2, nothing written.
    std::fs::write(d.join("bad.toml"), "x = [1.0, -1.0]\ny = [-1.0, 1.0]\n").unwrap();
    assert_all_fail(
        d,
        &[
            ("rollout --policy k.fzq --plant model", "rapier plant"),
            ("rollout --policy k.fzq --x0 -3,2,1,0", "at rest"),
            ("rollout --policy k.fzq --radius 0.1", "--radius"),
            (
                "rollout --policy k.fzq --x0 -3,2,0,0 --headings x",
                "--headings: value 1",
            ),
            ("rollout --policy k.fzq --x0 6,0,0,0", "robot"),
            (
                "train --env pointmass --arena arena.toml --out x.fzq",
                "--arena",
            ),
            (
                "train --env khepera --config one.toml --arena bad.toml --out x.fzq",
                "arena",
            ),
            // A policy learned from samples acts greedily; VQQL learns the point masses only.
            (
                "rollout --policy f.fzq --policy-kind interpolated",
                "--policy-kind: a policy learned from samples",
            ),
            // Regression: a radius beyond single precision was accepted (inf was refused).
            (
                "rollout --policy f.fzq --plant rapier --radius 1e39",
                "--radius: expected a positive number within single precision",
            ),
            (
                "rollout --policy f.fzq --plant rapier --radius inf",
                "--radius",
            ),
            (
                "train --env khepera --learner vqql --out y.fzq",
                "pointmass environment only",
            ),
        ],
    );
    assert!(!d.join("x.fzq").exists());
    assert!(!d.join("y.fzq").exists());
}

#[test]
fn compare_writes_the_table_and_figures() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    let o = fuzzyq(
        &[
            "compare",
            "--config",
            "one.toml",
            "--x0=-4,5,0,0",
            "--starts",
            "6",
            "--steps",
            "80",
            "--episodes",
            "60",
            "--cells",
            "64",
            "--samples",
            "2000",
            "--batch-samples",
            "2000",
            "--curve",
            "300,3000",
            "--out",
            "cmp",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let table = String::from_utf8(o.stdout).unwrap();
    assert!(
        table.contains("| paper: CMOMMT | paper: fuzzy |"),
        "{table}"
    );
    let out = d.join("cmp");
    for f in ["table1.md", "table1.csv", "paths.png"] {
        assert!(out.join(f).is_file(), "{f}");
    }
    let learners = [
        "fqi",
        "crisp",
        "crisp-uniform",
        "fql",
        "fql-literal",
        "vqql",
        "learned-model",
        "fqi-samples",
        "vqql-batch",
    ];
    for l in learners {
        assert!(out.join(format!("rollout-{l}.png")).is_file(), "{l}");
    }
    let csv = std::fs::read_to_string(out.join("table1.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + learners.len());
    // The sample-efficiency curve: 2 budgets for each of the 6 learners from samples.
    let curve = std::fs::read_to_string(out.join("efficiency.csv")).unwrap();
    assert_eq!(curve.lines().count(), 1 + 2 * 6, "{curve}");
    assert!(curve.contains("learned-model,3000,"), "{curve}");
    assert!(out.join("efficiency.png").is_file());
    assert_eq!(
        json(&out.join("efficiency.json")).as_array().unwrap().len(),
        12
    );
    let j = json(&out.join("table1.json"));
    let reports = j["reports"].as_array().unwrap();
    let names: Vec<&str> = reports
        .iter()
        .map(|r| r["learner"].as_str().unwrap())
        .collect();
    assert_eq!(names, learners);
    // One agent from (-4, 5) at rest: fuzzy Q-iteration brings it into the reward region.
    let fqi = &reports[0];
    assert_eq!(fqi["iteration_unit"], "sweeps");
    assert!(fqi["time_to_goal_s"].as_f64().is_some(), "{fqi}");
    assert!(fqi["final_error_cm"].as_f64().unwrap() < 10.0, "{fqi}");
    // 2025 cores x 25 actions for every grid learner; 64 cells x 25 actions for VQQL.
    assert_eq!(fqi["parameters"], 2025 * 25);
    assert_eq!(reports[2]["parameters"], 2025 * 25);
    assert_eq!(reports[3]["parameters"], 2025 * 25);
    assert_eq!(reports[5]["parameters"], 64 * 25);
    assert_eq!(reports[3]["iterations"], 60);
    // The learned model (2,000 transitions) is the true one here: the same run as fqi's.
    let learned = &reports[6];
    assert_eq!(learned["parameters"], 2025 * 25);
    assert_eq!(learned["iteration_unit"], "sweeps");
    assert_eq!(learned["time_to_goal_s"], fqi["time_to_goal_s"]);
    // Fuzzy Q-iteration from samples: the one agent's own-state cores x 25 actions.
    let fitted = &reports[7];
    assert_eq!(fitted["parameters"], 2025 * 25);
    assert_eq!(fitted["iteration_unit"], "iterations");
    // Its crisp counterpart: VQQL's 64 cells x 25 actions, fitted on the same transitions.
    assert_eq!(reports[8]["parameters"], 64 * 25);
    assert_eq!(reports[8]["iteration_unit"], "iterations");
    assert_eq!(learned["success_rate"], fqi["success_rate"]);
    assert_eq!(j["trajectories"].as_array().unwrap().len(), learners.len());

    // Bad input: exit code 2, one line, nothing written (no output directory either).
    std::fs::write(d.join("file"), "x").unwrap();
    assert_all_fail(
        d,
        &[
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --learners fqi,foo",
                "invalid value 'foo' for '--learners",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --learners fqi,fqi",
                "fqi is named twice",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --env khepera",
                "point-mass task only",
            ),
            ("compare --config one.toml --out fresh --x0=1,2,3", "x0"),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --steps 0",
                "steps",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --samples 0",
                "samples",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --curve 10,0",
                "--curve",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --learners fqi --curve 10",
                "learns from samples",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --start-position 9",
                "start_position",
            ),
            (
                "compare --config one.toml --x0=-4,5,0,0 --out file",
                "not a directory",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --seeds 0",
                "seeds",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --reward dense",
                "--reward",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --vqql-sweep 16,0",
                "--vqql-sweep",
            ),
            (
                "compare --config one.toml --out fresh --x0=-4,5,0,0 --cells 8 --vqql-sweep 16",
                "--cells",
            ),
        ],
    );
    assert!(!d.join("fresh").exists());
}

#[test]
fn compare_runs_the_learners_from_samples_over_seeds_under_the_shaped_reward() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    let o = fuzzyq(
        &[
            "compare",
            "--config",
            "one.toml",
            "--x0=-4,5,0,0",
            "--starts",
            "4",
            "--steps",
            "40",
            "--episodes",
            "20",
            "--learners",
            "fqi,fql,vqql",
            "--reward",
            "shaped",
            "--seeds",
            "2",
            "--vqql-sweep",
            "8,16",
            "--out",
            "cmp",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let err = stderr(&o);
    assert!(err.contains("vqql: seed 8, 16 cells per agent"), "{err}");
    let j = json(&d.join("cmp/table1.json"));
    assert_eq!(j["reward"], "shaped");
    let reports = j["reports"].as_array().unwrap();
    assert!(reports[0]["over_seeds"].is_null(), "fqi plans once");
    for r in &reports[1..] {
        assert_eq!(r["over_seeds"]["seeds"], serde_json::json!([7, 8]), "{r}");
    }
    assert_eq!(j["seed_trajectories"][1].as_array().unwrap().len(), 1);
    let sweep = j["vqql_sweep"].as_array().unwrap();
    assert_eq!(sweep.len(), 2);
    let table = std::fs::read_to_string(d.join("cmp/table1.md")).unwrap();
    assert!(table.contains("| cells per agent |"), "{table}");
    assert!(d.join("cmp/paths.png").is_file());
}

#[test]
fn point_mass_learners_from_samples_train_and_roll_out() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    for (learner, extra) in [
        ("fql", vec![]),
        ("fql", vec!["--literal"]),
        ("vqql", vec!["--cells", "16"]),
    ] {
        let mut args = vec![
            "train",
            "--config",
            "one.toml",
            "--learner",
            learner,
            "--episodes",
            "30",
            "--seed",
            "3",
            "--out",
            "p.fzq",
            "--curve",
            "c.csv",
            "--plot",
            "c.png",
            "--json",
            "s.json",
            "-q",
        ];
        args.extend(extra.iter().copied());
        let o = fuzzyq(&args, d);
        assert!(o.status.success(), "{learner}: {}", stderr(&o));
        let s = json(&d.join("s.json"));
        assert_eq!(s["learner"], learner);
        assert_eq!(s["episodes"], 30);
        let literal = if extra.first() == Some(&"--literal") {
            "literal"
        } else {
            "corrected"
        };
        assert_eq!(s["update"], literal);
        assert_eq!(
            std::fs::read_to_string(d.join("c.csv"))
                .unwrap()
                .lines()
                .count(),
            31
        );
        assert!(d.join("c.png").is_file());
        let o = fuzzyq(
            &[
                "rollout",
                "--policy",
                "p.fzq",
                "--x0=-4,5,0,0",
                "--steps",
                "20",
                "--json",
                "r.json",
            ],
            d,
        );
        assert!(o.status.success(), "{learner}: {}", stderr(&o));
        let r = json(&d.join("r.json"));
        assert_eq!(r["steps"], 20);
        assert_eq!(r["policy_kind"], "greedy");
        // ... and in the rapier world as well.
        let o = fuzzyq(
            &[
                "rollout",
                "--policy",
                "p.fzq",
                "--x0=-4,5,0,0",
                "--plant",
                "rapier",
                "--steps",
                "20",
                "--json",
                "rr.json",
            ],
            d,
        );
        assert!(o.status.success(), "{learner}: {}", stderr(&o));
        assert_eq!(json(&d.join("rr.json"))["steps"], 20);
    }
    assert_all_fail(
        d,
        &[
            (
                "train --config one.toml --cells 5 --out z.fzq",
                "--cells applies",
            ),
            (
                "train --config one.toml --learner vqql --cells 0 --out z.fzq",
                "vqql.cells",
            ),
        ],
    );
    assert!(!d.join("z.fzq").exists());
}

/// `--learner learned-model` on one noisy point mass: the model is learned from the plant,
/// the fit report lands in the JSON, the policy file carries the tables and rolls out like
/// the exact model's on the same grid, and bad input is refused.
#[test]
fn learned_model_trains_from_interaction_and_rolls_out() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let one = std::fs::read_to_string(one_agent_config(d)).unwrap();
    assert!(one.contains("velocity_noise = 0.0 "));
    std::fs::write(
        d.join("noisy.toml"),
        one.replace("velocity_noise = 0.0 ", "velocity_noise = 0.05"),
    )
    .unwrap();
    for (config, out) in [("one.toml", "l.fzq"), ("noisy.toml", "n.fzq")] {
        let args = [
            "train",
            "--config",
            config,
            "--learner",
            "learned-model",
            "--samples",
            "3000",
            "--seed",
            "4",
            "--out",
            out,
            "--json",
            "s.json",
            "-q",
        ];
        let o = fuzzyq(&args, d);
        assert!(o.status.success(), "{config}: {}", stderr(&o));
        let s = json(&d.join("s.json"));
        let l = &s["learned_model"];
        assert_eq!(l["samples"], 3000);
        assert_eq!(l["fit"]["blocks"].as_array().unwrap().len(), 2);
        let err = l["table_error"][0]["max_l1"].as_f64().unwrap();
        if config == "one.toml" {
            assert!(err < 1e-9, "noise-free tables are exact: {err}");
        } else {
            assert!(err > 1e-3, "noise spreads the rows: {err}");
        }
    }
    // Without noise the learned tables are the true ones: the same policy as the model's.
    let o = fuzzyq(
        &["train", "--config", "one.toml", "--out", "e.fzq", "-q"],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    for policy in ["l.fzq", "e.fzq", "n.fzq"] {
        let o = fuzzyq(
            &[
                "rollout",
                "--policy",
                policy,
                "--starts",
                "10",
                "--json",
                &format!("{policy}.json"),
            ],
            d,
        );
        assert!(o.status.success(), "{policy}: {}", stderr(&o));
    }
    let (l, e) = (json(&d.join("l.fzq.json")), json(&d.join("e.fzq.json")));
    assert_eq!(l["success_rate"], e["success_rate"]);
    assert!(e["success_rate"].as_f64().unwrap() > 0.5, "{e}");
    // Logged transitions from a CSV file: the same exact tables.
    let task = fuzzyq_sim::TrainConfig::from_toml(&one)
        .unwrap()
        .build_model()
        .unwrap();
    let collection = fuzzyq_sim::learn::samples::Collection {
        samples: 2000,
        episode_steps: 50,
        seed: 9,
    };
    let data = fuzzyq_sim::train::collect_from_plant(
        &task,
        &collection,
        &mut fuzzyq_sim::learn::samples::Exploration::Random,
    )
    .unwrap();
    let mut csv = String::from("s_x,s_y,v_x,v_y,u_x,u_y,s_x',s_y',v_x',v_y',r\n");
    for i in 0..data.len() {
        let (x, u, n, r) = data.get(i);
        let row: Vec<String> = x
            .iter()
            .chain(u)
            .chain(n)
            .chain([&r])
            .map(f64::to_string)
            .collect();
        csv.push_str(&row.join(","));
        csv.push('\n');
    }
    std::fs::write(d.join("t.csv"), csv).unwrap();
    std::fs::write(d.join("bad.csv"), "1,2,3\n").unwrap();
    let args = [
        "train",
        "--config",
        "one.toml",
        "--learner",
        "learned-model",
        "--transitions",
        "t.csv",
        "--out",
        "t.fzq",
        "--json",
        "t.json",
        "-q",
    ];
    let o = fuzzyq(&args, d);
    assert!(o.status.success(), "{}", stderr(&o));
    let l = &json(&d.join("t.json"))["learned_model"];
    assert_eq!(l["source"], "t.csv");
    assert_eq!(l["samples"], 2000);
    assert!(
        l["table_error"][0]["max_l1"].as_f64().unwrap() < 1e-9,
        "{l}"
    );
    assert_all_fail(
        d,
        &[
            (
                "train --config one.toml --transitions t.csv --out z.fzq",
                "--transitions applies",
            ),
            (
                "train --config one.toml --learner learned-model --transitions none.csv --out z.fzq",
                "cannot read",
            ),
            (
                "train --config one.toml --learner learned-model --transitions bad.csv --out z.fzq",
                "line 1: 3 values, expected 11",
            ),
            (
                "train --config one.toml --samples 100 --out z.fzq",
                "--samples applies",
            ),
            (
                "train --config one.toml --learner learned-model --samples 0 --out z.fzq",
                "samples",
            ),
            (
                "train --env carhill --learner learned-model --out z.fzq",
                "terminal",
            ),
            (
                "train --config one.toml --learner learned-model --rounds 0 --out z.fzq",
                "rounds",
            ),
            (
                "train --config one.toml --learner learned-model --rounds 2 --epsilon 1.5 --out z.fzq",
                "epsilon",
            ),
            (
                "train --config one.toml --learner learned-model --rounds 2 --epsilon nan --out z.fzq",
                "epsilon",
            ),
            (
                "train --config one.toml --rounds 2 --out z.fzq",
                "--rounds applies",
            ),
            (
                "train --config one.toml --learner learned-model --epsilon 0.2 --out z.fzq",
                "--rounds",
            ),
            (
                "train --config one.toml --learner learned-model --rounds 2 --transitions t.csv --out z.fzq",
                "--transitions",
            ),
        ],
    );
}

/// `--rounds`: each further round collects as many transitions epsilon-greedily with the
/// policy so far and refits on all of them; the JSON lists the rounds.
#[test]
fn learned_model_rounds_refit_on_everything_collected() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    let train = "train --config one.toml --learner learned-model --samples 500 --rounds 2 \
                 --epsilon 0.2 --out r.fzq --json r.json";
    let o = fuzzyq(&train.split_whitespace().collect::<Vec<_>>(), d);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("round 2: 1000 transitions"),
        "{}",
        stderr(&o)
    );
    let l = &json(&d.join("r.json"))["learned_model"];
    assert_eq!(l["samples"], 1000);
    assert_eq!(l["epsilon"], 0.2);
    let rounds = l["rounds"].as_array().unwrap();
    assert_eq!(rounds.len(), 2);
    assert_eq!(rounds[0]["transitions"], 500);
    assert_eq!(rounds[1]["transitions"], 1000);
    let o = fuzzyq(&["rollout", "--policy", "r.fzq", "--starts", "20"], d);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// A Khepera robot learns its kinematics from interaction with the rapier plant (wheel
/// noise on), and its policy of the learned model reaches the goal from random starts.
#[test]
fn khepera_learns_its_kinematics_on_the_rapier_plant() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let o = fuzzyq(&["config", "--env", "khepera"], d);
    assert!(o.status.success());
    let text = String::from_utf8(o.stdout).unwrap();
    assert!(text.contains("wheel_std = 0.0 "), "{text}");
    let one = text
        .replace("agents = 2 ", "agents = 1 ")
        .replace("wheel_std = 0.0 ", "wheel_std = 0.05");
    std::fs::write(d.join("one.toml"), one).unwrap();
    let train = "train --env khepera --config one.toml --learner learned-model --samples 3000 \
                 --seed 1 --out l.fzq --json l.json -q";
    let o = fuzzyq(&train.split_whitespace().collect::<Vec<_>>(), d);
    assert!(o.status.success(), "{}", stderr(&o));
    let l = json(&d.join("l.json"));
    let learned = &l["learned_model"];
    assert_eq!(learned["samples"], 3000);
    assert_eq!(learned["fit"]["blocks"].as_array().unwrap().len(), 1);
    let err = learned["table_error"][0]["mean_l1"].as_f64().unwrap();
    assert!(err < 0.15, "rows close to the kinematic model's: {err}");
    let rollout = "rollout --policy l.fzq --starts 10 --seed 7 --steps 300 --json r.json";
    let o = fuzzyq(&rollout.split_whitespace().collect::<Vec<_>>(), d);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = json(&d.join("r.json"));
    assert!(r["success_rate"].as_f64().unwrap() >= 0.9, "{r}");
    assert_eq!(r["runs_with_collisions"], 0, "{r}");
    // The README's noisy example is the default configuration with the plant's noise on.
    let example =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/khepera-noisy.toml");
    let example =
        fuzzyq_sim::TrainConfig::from_toml(&std::fs::read_to_string(example).unwrap()).unwrap();
    let fuzzyq_sim::io::config::EnvConfig::Khepera(k) = &example.env else {
        panic!("not khepera")
    };
    assert_eq!(k.noise.wheel_std, 0.05);
    assert_eq!(k.agents, 2);
}

#[test]
fn classic_benchmarks_train_roll_out_and_evaluate() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for env in ["dcmotor", "pendulum"] {
        let o = fuzzyq(&["config", "--env", env, "--preset", "toolbox-demo"], d);
        assert!(o.status.success(), "{}", stderr(&o));
        let text = String::from_utf8(o.stdout).unwrap();
        assert!(text.contains(&format!("kind = \"{env}\"")), "{text}");
        std::fs::write(d.join("c.toml"), &text).unwrap();
        let o = fuzzyq(
            &[
                "train", "--env", env, "--config", "c.toml", "--out", "p.fzq", "--json", "t.json",
                "-q",
            ],
            d,
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let t = json(&d.join("t.json"));
        assert_eq!(t["converged"], true);
        // The toolbox's own iteration: 79 and 364 iterations on these presets.
        let o = fuzzyq(
            &[
                "train",
                "--env",
                env,
                "--config",
                "c.toml",
                "--operator",
                "q-values",
                "--out",
                "q.fzq",
                "--json",
                "q.json",
                "-q",
            ],
            d,
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let want = if env == "dcmotor" { 79 } else { 364 };
        assert_eq!(json(&d.join("q.json"))["sweeps"], want);
        let o = fuzzyq(
            &[
                "rollout",
                "--policy",
                "p.fzq",
                "--x0=-1,0",
                "--steps",
                "100",
                "--plot",
                "r.png",
                "--maps",
                "m.png",
                "--csv",
                "r.csv",
                "--json",
                "r.json",
            ],
            d,
        );
        assert!(o.status.success(), "{}", stderr(&o));
        assert!(d.join("r.png").is_file() && d.join("m.png").is_file());
        assert_eq!(
            std::fs::read_to_string(d.join("r.csv"))
                .unwrap()
                .lines()
                .count(),
            102
        );
        let r = json(&d.join("r.json"));
        assert_eq!(r["steps"], 100);
        assert!(r["return"].as_f64().unwrap() < 0.0);
        let o = fuzzyq(
            &[
                "rollout", "--policy", "p.fzq", "--starts", "3", "--steps", "50", "--json",
                "mc.json",
            ],
            d,
        );
        assert!(o.status.success(), "{}", stderr(&o));
        let mc = json(&d.join("mc.json"));
        assert_eq!(mc["runs"].as_array().unwrap().len(), 9);
        assert_all_fail(
            d,
            &[
                ("rollout --policy p.fzq --x0=9,0", "outside the state range"),
                ("rollout --policy p.fzq --x0=1", "needs 2 values"),
                (
                    "rollout --policy p.fzq --plant rapier",
                    "--plant does not apply",
                ),
                ("rollout --policy p.fzq --starts 1", "at least 2 values"),
                (
                    "rollout --policy p.fzq --starts 3 --x0=0,0",
                    "--starts evaluates",
                ),
            ],
        );
    }
    // The car ends its run at the top of the hill; the arm has a 4-D state and two torques.
    for (env, x0, cols) in [("carhill", "--x0=-0.5,0", 5), ("arm", "--x0=-1,0,1,0", 8)] {
        let o = fuzzyq(
            &[
                "train", "--env", env, "--preset", "coarse", "--out", "p.fzq", "-q",
            ],
            d,
        );
        assert!(o.status.success(), "{env}: {}", stderr(&o));
        let o = fuzzyq(
            &[
                "rollout", "--policy", "p.fzq", x0, "--plot", "r.png", "--csv", "r.csv", "--json",
                "r.json",
            ],
            d,
        );
        assert!(o.status.success(), "{env}: {}", stderr(&o));
        let csv = std::fs::read_to_string(d.join("r.csv")).unwrap();
        assert_eq!(
            csv.lines().next().unwrap().split(',').count(),
            cols,
            "{csv}"
        );
        let r = json(&d.join("r.json"));
        if env == "carhill" {
            assert_eq!(r["terminal"], true, "{r}");
            assert!(r["return"].as_f64().unwrap() > 0.0, "{r}");
        } else {
            assert_all_fail(d, &[("rollout --policy p.fzq --maps m.png", "2-D")]);
        }
    }
    assert_all_fail(
        d,
        &[
            (
                "config --env dcmotor --preset huge",
                "unknown dcmotor preset",
            ),
            ("config --env pointmass --preset fine", "has no presets"),
            (
                "train --env dcmotor --preset fine --config c.toml --out x.fzq",
                "either --config or --preset",
            ),
        ],
    );
    assert!(!d.join("x.fzq").exists());
}

#[test]
fn bench_reports_the_machine_and_the_backup_against_the_peak() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    let o = fuzzyq(
        &[
            "bench",
            "--config",
            "one.toml",
            "--kernel",
            "scalar",
            "--backups",
            "2",
            "--peak-seconds",
            "0.05",
            "--json",
            "b.json",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8(o.stdout).unwrap();
    for line in ["cpu ", "caches ", "kernels ", "FMA peak ", "backup "] {
        assert!(out.contains(line), "{line:?} missing from {out}");
    }
    let j = json(&d.join("b.json"));
    assert_eq!(j["kernel"], "scalar");
    assert_eq!(j["backup"], "block");
    assert_eq!(j["backup_seconds"].as_array().unwrap().len(), 2);
    assert!(j["peak_gfma_per_second"].as_f64().unwrap() > 0.0);
    // The peak again after each of the three sweeps, and each timed backup against the two
    // measured around it; the fraction reported is their median (of two: the mean).
    let peaks = j["peaks_between_backups"].as_array().unwrap();
    assert_eq!(peaks.len(), 3);
    assert!(peaks.iter().all(|p| p.as_f64().unwrap() > 0.0), "{peaks:?}");
    let fs: Vec<f64> = j["fractions_of_peak"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f.as_f64().unwrap())
        .collect();
    assert_eq!(fs.len(), 2);
    assert!(fs.iter().all(|f| *f > 0.0 && f.is_finite()), "{fs:?}");
    let f = j["fraction_of_peak"].as_f64().unwrap();
    assert!(
        (f - 0.5 * (fs[0] + fs[1])).abs() <= 1e-12 * f,
        "fraction {f}"
    );
    assert!(out.contains("between the sweeps"), "{out}");
    assert!(j["kernels"].as_array().unwrap().contains(&"scalar".into()));

    assert_all_fail(
        d,
        &[
            ("bench --backups 0", "--backups must be at least 1"),
            (
                "bench --peak-seconds 0",
                "--peak-seconds must be in (0, 60]",
            ),
            (
                "bench --config missing.toml",
                "cannot read config missing.toml",
            ),
            ("bench --threads 0", "--threads: expected 1 to"),
        ],
    );
}

#[test]
fn export_writes_the_compact_policy_and_refuses_what_it_cannot_export() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let config = one_agent_config(d);
    let o = fuzzyq(
        &[
            "train",
            "--config",
            config.to_str().unwrap(),
            "--out",
            "p.fzq",
            "--quiet",
        ],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    for (extra, out) in [(None, "p.bin"), (Some("--no-values"), "p-small.bin")] {
        let mut args = vec!["export", "--policy", "p.fzq", "--out", out];
        args.extend(extra);
        let o = fuzzyq(&args, d);
        assert!(o.status.success(), "{}", stderr(&o));
        let bytes = std::fs::read(d.join(out)).unwrap();
        assert!(bytes.starts_with(b"\x89FZQVIEW"));
        assert!(stderr(&o).contains(&format!("{} bytes", bytes.len())));
    }
    let (full, small) = (
        std::fs::metadata(d.join("p.bin")).unwrap().len(),
        std::fs::metadata(d.join("p-small.bin")).unwrap().len(),
    );
    // V is 4 bytes a core in f32; the greedy actions one byte (25 joint actions).
    assert!(small < full / 3, "{small} against {full}");
    std::fs::write(d.join("not-a-policy"), "hello").unwrap();
    assert_all_fail(
        d,
        &[
            ("export --policy missing.fzq --out x.bin", "missing.fzq"),
            ("export --policy not-a-policy --out x.bin", "not-a-policy"),
            ("export --policy p.fzq --out p.fzq", "would overwrite"),
            (
                "export --policy p.fzq --out no/such/dir/x.bin",
                "no/such/dir",
            ),
            ("export --out x.bin", "--policy"),
        ],
    );
}
