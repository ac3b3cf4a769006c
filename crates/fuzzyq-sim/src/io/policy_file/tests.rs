//! Policy files: encoding, decoding, damage and the older versions.

use std::ops::ControlFlow;

use super::*;
use crate::io::config::{GridConfig, TrainConfig};
use crate::learn::tasks::khepera as kt;

pub(super) fn tiny() -> PolicyArtifact {
    let config = TrainConfig {
        grid: GridConfig {
            position_cores: vec![-1.0, 1.0],
            velocity_cores: vec![-1.0, 1.0],
            heading_divisions: None,
            cores: None,
            membership: Default::default(),
        },
        ..TrainConfig::default()
    };
    PolicyArtifact {
        config,
        values: Values::F32(vec![1.5; 256]),
        greedy: vec![7; 256],
        learned: None,
        summary: TrainSummary {
            sweeps: 3,
            converged: true,
            final_delta: 0.01,
            deltas: vec![(5.0, 5.0), (0.1, 0.2), (0.01, 0.01)],
            extrapolated: vec![2],
            seconds: 0.0,
            sweep_bound: 200,
            reward_bound: 5.0,
            backup: "block".into(),
            kernel: "scalar".into(),
            multiply_adds_per_sweep: Some(1e6),
            sweep_seconds: 0.0,
            fuzzyq_version: "test".into(),
            evaluation: Vec::new(),
            evaluation_seconds: 0.0,
            coarse: None,
            setup_seconds: None,
            result_seconds: None,
        },
    }
}

/// `bytes` decoded in memory, after checking that a file of them decoded as it is read
/// gives the same file or the same error.
pub(super) fn decode(bytes: &[u8]) -> Result<PolicyFile, PolicyFileError> {
    crate::io::container::read_both_ways(bytes, PolicyFile::from_bytes, |path| {
        PolicyFile::load_streaming_from(path, 0)
    })
}

/// The same run gives the same bytes: the timings, which differ between identical runs,
/// are not stored.
#[test]
fn files_keep_no_timings() {
    let timed = |seconds: f64| {
        let mut a = tiny();
        (a.summary.seconds, a.summary.sweep_seconds) = (seconds, seconds / 2.0);
        PolicyFile::Fqi(a).to_bytes().unwrap()
    };
    assert_eq!(timed(0.5), timed(7.25));
    let PolicyFile::Fqi(back) = decode(&timed(0.5)).unwrap() else {
        unreachable!("an fqi file")
    };
    assert_eq!(back.summary.seconds, 0.0);
    assert_eq!(back, tiny());
}

#[test]
fn round_trips_and_refuses_damage() {
    let a = PolicyFile::Fqi(tiny());
    let bytes = a.to_bytes().unwrap();
    assert_eq!(decode(&bytes).unwrap(), a);

    let e = decode(&bytes[..bytes.len() - 10]).unwrap_err();
    assert!(matches!(e, PolicyFileError::Truncated { .. }), "{e}");
    let e = decode(&bytes[..5]).unwrap_err();
    assert!(matches!(e, PolicyFileError::Truncated { .. }), "{e}");
    let e = decode(b"[env]\nkind = 1\n").unwrap_err();
    assert!(matches!(e, PolicyFileError::NotAPolicy { .. }), "{e}");
    let e = decode(b"").unwrap_err();
    assert!(matches!(e, PolicyFileError::NotAPolicy { .. }), "{e}");
    let e = decode(&[0xff, 0xfe, 0x00]).unwrap_err();
    assert!(matches!(e, PolicyFileError::NotAPolicy { .. }), "{e}");

    let mut flipped = bytes.clone();
    let last = flipped.len() - 1;
    flipped[last] ^= 1;
    let e = decode(&flipped).unwrap_err();
    assert!(matches!(e, PolicyFileError::Checksum { .. }), "{e}");

    let mut v6 = bytes.clone();
    v6[8] = 6;
    let e = decode(&v6).unwrap_err();
    assert!(
        matches!(e, PolicyFileError::Version { found: 6, .. }),
        "{e}"
    );
    assert!(e.to_string().contains("versions 1 to 5"), "{e}");

    let mut bad = tiny();
    bad.greedy[0] = 625;
    let e = decode(&PolicyFile::Fqi(bad).to_bytes().unwrap()).unwrap_err();
    assert!(e.to_string().contains("out of range"), "{e}");
}

/// Regression (issue 49): bytes appended inside the checksummed payload were ignored, and
/// undecodable payloads showed postcard's own messages.
#[test]
fn a_payload_must_hold_its_content_and_nothing_more() {
    let bytes = PolicyFile::Fqi(tiny()).to_bytes().unwrap();
    let version = u32::from_le_bytes(bytes[8..12].try_into().unwrap());
    let reseal = |payload: &[u8]| super::super::container::encode(&MAGIC, version, payload);
    let payload = &bytes[super::super::container::HEADER_LEN..];
    let mut longer = payload.to_vec();
    longer.extend_from_slice(&[0, 1, 2]);
    let e = decode(&reseal(&longer)).unwrap_err();
    assert!(matches!(e, PolicyFileError::Malformed { .. }), "{e}");
    assert!(e.to_string().contains("3 bytes after its content"), "{e}");
    let e = decode(&reseal(&payload[..payload.len() - 4])).unwrap_err();
    assert!(e.to_string().contains("ends inside its content"), "{e}");
    let mut kind = payload.to_vec();
    kind[0] = 0x7f; // the payload's kind: no such variant
    let e = decode(&reseal(&kind)).unwrap_err().to_string();
    assert!(e.contains("wrong kind or out of range"), "{e}");
    for leak in ["Serde", "wasn't", "usize", "Deserialization"] {
        assert!(!e.contains(leak), "{e}");
    }
}

/// Regression: a 40-byte file whose header announces a terabyte payload and whose first
/// string claims a terabyte was decoded as it is read, and the string's buffer was
/// allocated at the claimed length: the process aborted. Now it is a truncated file.
#[test]
fn a_string_longer_than_the_file_allocates_nothing_ahead() {
    let varint = |mut n: u64| {
        let mut out = Vec::new();
        while n >= 0x80 {
            out.push((n as u8) | 0x80);
            n >>= 7;
        }
        out.push(n as u8);
        out
    };
    let mut file = MAGIC.to_vec();
    file.extend_from_slice(&2u32.to_le_bytes());
    file.extend_from_slice(&(1u64 << 45).to_le_bytes());
    file.extend_from_slice(&0u32.to_le_bytes());
    file.extend(varint(0)); // fuzzy Q-iteration
    file.extend(varint(1 << 40)); // its configuration's length
    file.extend_from_slice(b"[env]");
    let e = decode(&file).unwrap_err();
    assert!(matches!(e, PolicyFileError::Truncated { .. }), "{e}");
}

/// A solution of a model defined in Python decodes alike in memory and as it is read
/// (its membership functions are named: a name is read as a transient string, which a
/// stream can give).
#[test]
fn tabulated_solutions_decode_as_they_are_read() {
    let a = tiny();
    let t = TabulatedArtifact {
        cores: vec![vec![-1.0, 1.0]; 2],
        membership: fuzzyq_core::Membership::Crisp,
        actions: vec![(vec![-1.0, 1.0], 1)],
        blocks: Vec::new(),
        values: Values::F64(vec![0.5; 4]),
        greedy: vec![1; 4],
        gamma: 0.9,
        xi: 0.01,
        absorbing_goal: false,
        summary: a.summary,
    };
    let file = PolicyFile::Tabulated(Box::new(t));
    let back = decode(&file.to_bytes().unwrap());
    assert!(
        back.is_ok() || !back.unwrap_err().to_string().contains("wrong kind"),
        "decodes"
    );
}

/// Files of format version 1 (fuzzy Q-iteration only, no payload kind) still load.
#[test]
fn version_1_files_still_load() {
    let a = tiny();
    let payload = postcard::to_stdvec(&FqiPayloadRef {
        config_toml: a.config.to_toml(),
        values: &a.values,
        greedy: &a.greedy,
        summary: &a.summary,
    })
    .unwrap();
    let v1 = crate::io::container::encode(&MAGIC, 1, &payload);
    assert_eq!(decode(&v1).unwrap(), PolicyFile::Fqi(a));
    // Version 2 is the same payload behind its kind.
    let v2 = PolicyFile::Fqi(tiny()).to_bytes().unwrap();
    assert_eq!(&v2[..8], &MAGIC);
    assert_eq!(v2[8], 2);
    assert_eq!(v2[24], 0, "the payload kind of fuzzy Q-iteration");
    assert_eq!(&v2[25..], &payload[..]);
}

#[test]
fn save_is_atomic_and_loads_through_a_pipe() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("policy.fzq");
    let a = PolicyFile::Fqi(tiny());
    a.save(&path).unwrap();
    assert_eq!(PolicyFile::load(&path).unwrap(), a);
    // Only the destination remains: no temporary files.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    let missing = dir.path().join("no/such/dir/p.fzq");
    assert!(a.save(&missing).is_err());
    assert!(!missing.exists());
    let e = PolicyFile::load(&dir.path().join("missing.fzq")).unwrap_err();
    assert!(e.to_string().contains("cannot read"), "{e}");
    // The loader reads a file once: a FIFO (a policy fed through a pipe) works.
    #[cfg(unix)]
    {
        let fifo = dir.path().join("fifo");
        let status = std::process::Command::new("mkfifo").arg(&fifo).status();
        if status.is_ok_and(|s| s.success()) {
            let bytes = a.to_bytes().unwrap();
            let writer = {
                let fifo = fifo.clone();
                std::thread::spawn(move || std::fs::write(fifo, bytes).unwrap())
            };
            assert_eq!(PolicyFile::load(&fifo).unwrap(), a);
            writer.join().unwrap();
        }
    }
}

#[test]
fn khepera_policy_files_round_trip_and_are_checked() {
    let config = crate::model::khepera::KheperaConfig::default();
    let fql = FqlConfig {
        episodes: 2,
        max_steps: 5,
        eval_every: 0,
        ..kt::default_fql_config()
    };
    let out = kt::train_fql(&config, &fql, |_: &crate::learn::fql::EpisodeRecord| {
        ControlFlow::Continue(())
    })
    .unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fql.fzq");
    let file = KheperaPolicyFile::from_outcome(&config, &fql, &out);
    PolicyFile::Khepera(file.clone()).save(&path).unwrap();
    assert_eq!(
        PolicyFile::load(&path).unwrap(),
        PolicyFile::Khepera(file.clone())
    );
    // The plain TOML of files written before version 2 still loads, and is checked.
    let toml_path = dir.path().join("fql.toml");
    std::fs::write(&toml_path, toml::to_string(&file).unwrap()).unwrap();
    assert_eq!(
        PolicyFile::load(&toml_path).unwrap(),
        PolicyFile::Khepera(file.clone())
    );
    let mut other = file.clone();
    other.config.sonar_levels = [0.4, 1.0];
    std::fs::write(&toml_path, toml::to_string(&other).unwrap()).unwrap();
    let err = PolicyFile::load(&toml_path).unwrap_err().to_string();
    assert!(
        err.contains("fql.toml") && err.contains("feature space"),
        "{err}"
    );
    let err = PolicyFile::from_bytes(
        &PolicyFile::Khepera(other).to_bytes().unwrap(),
        Path::new("x.fzq"),
    )
    .unwrap_err()
    .to_string();
    assert!(err.contains("feature space"), "{err}");
}

/// Header lengths near 2^64 do not overflow.
#[test]
fn impossible_lengths_are_refused() {
    let bytes = PolicyFile::Fqi(tiny()).to_bytes().unwrap();
    for len in [u64::MAX, u64::MAX - 23, u64::MAX - 24] {
        let mut b = bytes.clone();
        b[12..20].copy_from_slice(&len.to_le_bytes());
        let e = decode(&b).unwrap_err();
        assert!(
            matches!(
                e,
                PolicyFileError::Malformed { .. } | PolicyFileError::Truncated { .. }
            ),
            "{e}"
        );
    }
}
