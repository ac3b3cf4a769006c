//! Output files as one transaction: no output over another or over an input, special files
//! written in place and never replaced, links kept, stale temporaries of killed runs removed.

use std::path::Path;

use super::{assert_all_fail, fuzzyq, one_agent_config, stderr};

/// `fuzzyq rollout` of `p.fzq` (see [`trained`]) from `(-4, 5)` at rest, with `rest`.
fn rollout(d: &Path, rest: &[&str]) -> std::process::Output {
    let mut args = vec!["rollout", "--policy", "p.fzq", "--x0=-4,5,0,0"];
    args.extend_from_slice(rest);
    fuzzyq(&args, d)
}

/// A trained one-agent policy `p.fzq` and its config `one.toml` in `d`.
fn trained(d: &Path) {
    one_agent_config(d);
    let o = fuzzyq(
        &["train", "--config", "one.toml", "--out", "p.fzq", "-q"],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn outputs_over_each_other_or_over_inputs_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trained(d);
    std::fs::create_dir(d.join("sub")).unwrap();
    std::fs::copy(d.join("one.toml"), d.join("sub/table1.csv")).unwrap();
    std::fs::hard_link(d.join("one.toml"), d.join("hard.toml")).unwrap();
    std::fs::hard_link(d.join("p.fzq"), d.join("hard.fzq")).unwrap();
    #[cfg(unix)]
    {
        std::os::unix::fs::symlink("one.toml", d.join("link.toml")).unwrap();
        std::os::unix::fs::symlink("p.fzq", d.join("link.fzq")).unwrap();
    }
    assert_all_fail(
        d,
        &[
            // Two outputs on one file.
            (
                "train --config one.toml --out s.json --json s.json",
                "name the same file",
            ),
            (
                "train --config one.toml --out s.json --json ./s.json",
                "name the same file",
            ),
            (
                "train --config one.toml --out s.json --json sub/../s.json",
                "name the same file",
            ),
            (
                "train --config one.toml --out p.fzq --json hard.fzq",
                "name the same file",
            ),
            (
                "train --config one.toml --out p.fzq --json link.fzq",
                "name the same file",
            ),
            (
                "train --config one.toml --learner fql --episodes 2 --out f.fzq --curve c.csv --json c.csv",
                "name the same file",
            ),
            (
                "train --config one.toml --learner fql --episodes 2 --out f.fzq --curve f.fzq",
                "name the same file",
            ),
            (
                "rollout --policy p.fzq --csv r.csv --json r.csv",
                "name the same file",
            ),
            (
                "rollout --policy p.fzq --plot r.png --maps r.png",
                "name the same file",
            ),
            // An output over an input.
            (
                "train --config one.toml --out one.toml",
                "would overwrite the --config input",
            ),
            (
                "train --config one.toml --out p.fzq --json one.toml",
                "would overwrite the --config input",
            ),
            (
                "train --config one.toml --out hard.toml",
                "would overwrite the --config input",
            ),
            (
                "train --config one.toml --out link.toml",
                "would overwrite the --config input",
            ),
            (
                "train --config link.toml --out one.toml",
                "would overwrite the --config input",
            ),
            (
                "rollout --policy p.fzq --json p.fzq",
                "would overwrite the --policy input",
            ),
            (
                "rollout --policy p.fzq --csv hard.fzq",
                "would overwrite the --policy input",
            ),
            (
                "rollout --policy link.fzq --json p.fzq",
                "would overwrite the --policy input",
            ),
            (
                "compare --config sub/table1.csv --out sub --learners fqi --x0=-4,5,0,0",
                "would overwrite the --config input",
            ),
            // Not a file that can be written.
            ("train --config one.toml --out sub", "is a directory"),
            (
                "train --config one.toml --out missing/p.fzq",
                "does not exist",
            ),
            ("rollout --policy p.fzq --json sub", "is a directory"),
        ],
    );
}

#[cfg(unix)]
#[test]
fn devices_are_written_in_place_never_replaced() {
    use std::os::unix::fs::FileTypeExt;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trained(d);
    let o = fuzzyq(
        &[
            "train",
            "--config",
            "one.toml",
            "--out",
            "/dev/null",
            "--json",
            "/dev/null",
        ],
        d,
    );
    // Two outputs on one device are refused like two on one file.
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let o = fuzzyq(
        &["train", "--config", "one.toml", "--out", "/dev/null", "-q"],
        d,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = rollout(d, &["--json", "/dev/stdout"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.contains("\"reach_step\""),
        "the metrics on stdout: {out}"
    );
    let null = std::fs::symlink_metadata("/dev/null").unwrap();
    assert!(
        null.file_type().is_char_device(),
        "/dev/null is still a device"
    );
    // A link to a device is written through, not replaced.
    std::os::unix::fs::symlink("/dev/null", d.join("sink.json")).unwrap();
    let o = rollout(d, &["--json", "sink.json", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let link = std::fs::symlink_metadata(d.join("sink.json")).unwrap();
    assert!(link.file_type().is_symlink());
}

#[cfg(unix)]
#[test]
fn a_link_to_an_output_keeps_its_link_and_its_file_is_replaced() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trained(d);
    std::fs::create_dir(d.join("runs")).unwrap();
    std::fs::write(d.join("runs/m.json"), "old").unwrap();
    std::os::unix::fs::symlink("runs/m.json", d.join("latest.json")).unwrap();
    let o = rollout(d, &["--json", "latest.json", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::symlink_metadata(d.join("latest.json"))
            .unwrap()
            .file_type()
            .is_symlink()
    );
    let text = std::fs::read_to_string(d.join("runs/m.json")).unwrap();
    assert!(text.contains("reach_step"), "{text}");
    // No temporary left in either folder.
    for folder in [d, &d.join("runs")] {
        for e in std::fs::read_dir(folder).unwrap() {
            let name = e.unwrap().file_name();
            assert!(!name.to_string_lossy().starts_with(".fuzzyq-"), "{name:?}");
        }
    }
}

#[test]
fn stale_temporaries_of_killed_runs_are_removed_and_nothing_else() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    trained(d);
    let hour_and_more = std::time::SystemTime::now() - std::time::Duration::from_secs(7200);
    for name in [
        ".fuzzyq-old1.tmp",
        ".fuzzyq-old2.png",
        ".fuzzyq-new.tmp",
        ".other-old.tmp",
    ] {
        let f = std::fs::File::create(d.join(name)).unwrap();
        if name.contains("old") {
            f.set_modified(hour_and_more).unwrap();
        }
    }
    let o = rollout(d, &["--json", "m.json", "-q"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(!d.join(".fuzzyq-old1.tmp").exists());
    assert!(!d.join(".fuzzyq-old2.png").exists());
    // A recent one may belong to a run still going; another program's file is not ours.
    assert!(d.join(".fuzzyq-new.tmp").exists());
    assert!(d.join(".other-old.tmp").exists());
}

/// The same configuration and seed give the same policy file, byte for byte.
#[test]
fn identical_runs_write_identical_policy_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    one_agent_config(d);
    for learner in ["fqi", "learned-model --samples 500", "fql --episodes 5"] {
        let bytes = |name: &str| {
            let line = format!("train --config one.toml --learner {learner} --out {name} -q");
            let o = fuzzyq(&line.split_whitespace().collect::<Vec<_>>(), d);
            assert!(o.status.success(), "{line}: {}", stderr(&o));
            std::fs::read(d.join(name)).unwrap()
        };
        assert!(
            bytes("a.fzq") == bytes("b.fzq"),
            "{learner}: the files differ"
        );
    }
}
