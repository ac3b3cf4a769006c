//! Fuzzed parsers (issue 15: nothing a user types or feeds crashes fuzzyq): arbitrary bytes
//! and mutations of valid files (bytes flipped, inserted, deleted, duplicated, cut; TOML
//! tokens dropped in) fed to the policy-file loader (the binary container, its payload
//! re-sealed so that the decoder sees it, and the TOML of a policy learned from samples), the
//! configuration parser and the arena parser. Each must return (an error for broken input),
//! never panic, answer quickly, and say what is wrong on one line.
//!
//! The budget is fixed (256 cases per property, a fixed seed, no persisted failures), so the
//! suite runs in a few seconds in a debug build: `cargo test -p fuzzyq-tests --test
//! integration fuzz::`.

use std::fmt::Display;
use std::ops::ControlFlow;
use std::path::Path;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

use fuzzyq_sim::io::config::{DEFAULT_KHEPERA_TOML, DEFAULT_POINTMASS_TOML, EnvConfig};
use fuzzyq_sim::io::policy_file::{MAGIC, PointMassPolicyFile, PolicyFile};
use fuzzyq_sim::learn::fql::FqlConfig;
use fuzzyq_sim::learn::tasks::pointmass as pt;
use fuzzyq_sim::model::arena::Arena;
use fuzzyq_sim::model::pointmass::Starts;
use fuzzyq_sim::{PointMass, PointMassConfig, PolicyFileError, TrainConfig};
use proptest::prelude::*;
use proptest::test_runner::{RngAlgorithm, RngSeed};

/// The fixed budget of every property here.
fn budget() -> ProptestConfig {
    ProptestConfig {
        cases: 256,
        failure_persistence: None,
        rng_algorithm: RngAlgorithm::ChaCha,
        rng_seed: RngSeed::Fixed(15),
        ..ProptestConfig::default()
    }
}

/// The longest any one parse may take (debug build, a loaded machine).
const SLOW: Duration = Duration::from_secs(2);

const ARENA: &str = r#"# two obstacles
x = [-6.0, 6.0]
y = [-6.0, 6.0]

[[obstacle]]
shape = "box"
center = [-2.0, 2.5]
half_extents = [0.6, 0.05]
angle_deg = 38.66

[[obstacle]]
shape = "disc"
center = [2.0, -2.0]
radius = 0.3
"#;

/// A policy of fuzzy Q-iteration on one point mass (81 cores), as the library writes it.
fn fqi_bytes() -> &'static [u8] {
    static BYTES: OnceLock<Vec<u8>> = OnceLock::new();
    BYTES.get_or_init(|| {
        let mut c = TrainConfig {
            env: EnvConfig::Pointmass(PointMassConfig {
                agents: 1,
                ..PointMassConfig::default()
            }),
            ..TrainConfig::default()
        };
        c.grid.position_cores = vec![-6.0, 0.0, 6.0];
        c.grid.velocity_cores = vec![-3.0, 0.0, 3.0];
        let a = fuzzyq_sim::train::train(&c, |_| ControlFlow::Continue(())).expect("train");
        PolicyFile::Fqi(a).to_bytes().expect("encode")
    })
}

/// A point-mass policy learned by fuzzy Q-learning (a few episodes), as the library writes it.
fn fql_bytes() -> &'static [u8] {
    static BYTES: OnceLock<Vec<u8>> = OnceLock::new();
    BYTES.get_or_init(|| {
        let config = PointMassConfig {
            agents: 1,
            force_levels: vec![-2.0, 0.0, 2.0],
            goal_radius: 1.0,
            ..PointMassConfig::default()
        };
        let model = PointMass::new(config.clone()).unwrap();
        let starts = Starts::Uniform {
            position: 3.0,
            velocity: 0.0,
        };
        let fql = FqlConfig {
            episodes: 5,
            max_steps: 10,
            eval_every: 0,
            ..pt::default_fql_config()
        };
        let features = pt::feature_space(&model, &[-6.0, 0.0, 6.0], &[-3.0, 0.0, 3.0]).unwrap();
        let out = pt::train_fql(&model, &features, &starts, &fql, |_: &_| {
            ControlFlow::Continue(())
        })
        .unwrap();
        let file = PointMassPolicyFile::from_outcome(&config, &starts, &fql, None, &out);
        PolicyFile::PointMass(file).to_bytes().unwrap()
    })
}

/// The TOML text a learned policy's container holds (the plain TOML files of format 1 were
/// this text): the payload is postcard's variant index (1, a point-mass policy), the text's
/// length as a varint, then the text.
fn fql_toml() -> &'static str {
    static TEXT: OnceLock<String> = OnceLock::new();
    TEXT.get_or_init(|| {
        let payload = &fql_bytes()[24..];
        assert_eq!(payload[0], 1, "a point-mass policy");
        let (mut len, mut shift, mut at) = (0usize, 0, 1);
        loop {
            let b = payload[at];
            len |= usize::from(b & 0x7f) << shift;
            at += 1;
            shift += 7;
            if b & 0x80 == 0 {
                break;
            }
        }
        let text = std::str::from_utf8(&payload[at..at + len])
            .unwrap()
            .to_string();
        assert_eq!(at + len, payload.len());
        text
    })
}

/// The payload of a container with its header, its length and checksum made right again, so
/// that a mutated payload reaches the decoder.
fn seal(version: u32, payload: &[u8]) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    out.extend_from_slice(&version.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&crc32fast_hash(payload).to_le_bytes());
    out.extend_from_slice(payload);
    out
}

/// CRC-32 (IEEE), bitwise: the tests do not depend on crc32fast.
fn crc32fast_hash(bytes: &[u8]) -> u32 {
    let mut crc = !0u32;
    for &b in bytes {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = (crc >> 1) ^ (0xEDB8_8320 & (crc & 1).wrapping_neg());
        }
    }
    !crc
}

/// One mutation of a file.
#[derive(Clone, Debug)]
enum Op {
    Flip(prop::sample::Index, u8),
    Set(prop::sample::Index, u8),
    Insert(prop::sample::Index, Vec<u8>),
    Delete(prop::sample::Index, usize),
    Duplicate(prop::sample::Index, usize),
    Truncate(prop::sample::Index),
    /// A TOML token that often breaks or bends a document.
    Token(prop::sample::Index, &'static str),
}

const TOKENS: [&str; 24] = [
    "nan",
    "-inf",
    "1e400",
    "99999999999999999999999",
    "0x7fffffffffffffff",
    "-1",
    "0",
    "\"",
    "'",
    "[",
    "]",
    "{",
    "}",
    ",",
    "=",
    "\n",
    "#",
    ".",
    "\n[[obstacle]]\nshape = \"disc\"\n",
    "\n[env.arena]\n",
    ", 3.0",
    "\u{feff}",
    "\\u0000",
    "[[",
];

fn op() -> impl Strategy<Value = Op> {
    let i = any::<prop::sample::Index>;
    prop_oneof![
        (i(), 0..8u8).prop_map(|(i, b)| Op::Flip(i, b)),
        (i(), any::<u8>()).prop_map(|(i, b)| Op::Set(i, b)),
        (i(), prop::collection::vec(any::<u8>(), 1..8)).prop_map(|(i, b)| Op::Insert(i, b)),
        (i(), 1..64usize).prop_map(|(i, n)| Op::Delete(i, n)),
        (i(), 1..64usize).prop_map(|(i, n)| Op::Duplicate(i, n)),
        i().prop_map(Op::Truncate),
        (i(), prop::sample::select(TOKENS.to_vec())).prop_map(|(i, t)| Op::Token(i, t)),
    ]
}

fn mutations() -> impl Strategy<Value = Vec<Op>> {
    prop::collection::vec(op(), 1..6)
}

fn mutate(base: &[u8], ops: &[Op]) -> Vec<u8> {
    let mut b = base.to_vec();
    for op in ops {
        let at = |i: &prop::sample::Index, b: &Vec<u8>| i.index(b.len() + 1);
        match op {
            Op::Flip(i, bit) if !b.is_empty() => {
                let k = i.index(b.len());
                b[k] ^= 1 << bit;
            }
            Op::Set(i, v) if !b.is_empty() => {
                let k = i.index(b.len());
                b[k] = *v;
            }
            Op::Insert(i, v) => {
                let k = at(i, &b);
                b.splice(k..k, v.iter().copied());
            }
            Op::Token(i, t) => {
                let k = at(i, &b);
                b.splice(k..k, t.bytes());
            }
            Op::Delete(i, n) => {
                let k = at(i, &b);
                let end = (k + n).min(b.len());
                b.drain(k..end);
            }
            Op::Duplicate(i, n) => {
                let k = at(i, &b);
                let end = (k + n).min(b.len());
                let copy = b[k..end].to_vec();
                b.splice(end..end, copy);
            }
            Op::Truncate(i) => {
                let k = at(i, &b);
                b.truncate(k);
            }
            _ => {}
        }
    }
    b
}

/// Runs `parse` (a panic fails the case by itself) and checks the answer: in time, and an
/// error of one non-empty line.
fn check<T, E: Display>(
    what: &str,
    parse: impl FnOnce() -> Result<T, E>,
) -> Result<Option<T>, TestCaseError> {
    let start = Instant::now();
    let result = parse();
    let took = start.elapsed();
    prop_assert!(took < SLOW, "{what}: took {took:?}");
    match result {
        Ok(v) => Ok(Some(v)),
        Err(e) => {
            let m = e.to_string();
            prop_assert!(!m.trim().is_empty(), "{what}: an empty message");
            prop_assert!(
                !m.contains(['\n', '\r']),
                "{what}: a message of several lines: {m:?}"
            );
            prop_assert!(m.len() < 1500, "{what}: a message of {} bytes", m.len());
            Ok(None)
        }
    }
}

fn policy(bytes: &[u8]) -> Result<Option<PolicyFile>, TestCaseError> {
    check("policy file", || {
        PolicyFile::from_bytes(bytes, Path::new("p.fzq"))
    })
}

fn config(bytes: &[u8]) -> Result<(), TestCaseError> {
    let text = String::from_utf8_lossy(bytes);
    check("config", || TrainConfig::from_toml(&text)).map(drop)
}

fn arena(bytes: &[u8]) -> Result<(), TestCaseError> {
    let text = String::from_utf8_lossy(bytes);
    check("arena", || Arena::from_toml(&text)).map(drop)
}

proptest! {
    #![proptest_config(budget())]

    /// Arbitrary bytes, bare and behind the policy tag, and arbitrary text.
    #[test]
    fn arbitrary_bytes_are_refused_on_one_line(
        bytes in prop::collection::vec(any::<u8>(), 0..512),
        version in 0..6u32,
    ) {
        prop_assert!(policy(&bytes)?.is_none());
        let mut tagged = MAGIC.to_vec();
        tagged.extend_from_slice(&bytes);
        prop_assert!(policy(&tagged)?.is_none());
        policy(&seal(version, &bytes))?;
        config(&bytes)?;
        arena(&bytes)?;
    }

    /// A fuzzy Q-iteration policy with damage anywhere (mostly caught by the checksum), and
    /// with its payload damaged and re-sealed (the decoder and the checks see it).
    #[test]
    fn damaged_fqi_policies_are_refused_on_one_line(ops in mutations()) {
        let base = fqi_bytes();
        policy(&mutate(base, &ops))?;
        let payload = mutate(&base[24..], &ops);
        for version in [1, 2, 3, 4] {
            policy(&seal(version, &payload))?;
        }
    }

    /// A point-mass policy learned from samples, its container damaged and re-sealed, and its
    /// TOML damaged (in the container and as a plain TOML file).
    #[test]
    fn damaged_learned_policies_are_refused_on_one_line(ops in mutations()) {
        let base = fql_bytes();
        policy(&mutate(base, &ops))?;
        policy(&seal(2, &mutate(&base[24..], &ops)))?;
        let text = mutate(fql_toml().as_bytes(), &ops);
        policy(&text)?;
        if let Ok(text) = std::str::from_utf8(&text) {
            // The same text inside a container.
            let mut payload = vec![1u8];
            let mut n = text.len();
            loop {
                let b = (n & 0x7f) as u8;
                n >>= 7;
                payload.push(if n == 0 { b } else { b | 0x80 });
                if n == 0 {
                    break;
                }
            }
            payload.extend_from_slice(text.as_bytes());
            policy(&seal(2, &payload))?;
        }
    }

    /// The commented default configurations, damaged.
    #[test]
    fn damaged_configs_are_refused_on_one_line(ops in mutations()) {
        config(&mutate(DEFAULT_POINTMASS_TOML.as_bytes(), &ops))?;
        config(&mutate(DEFAULT_KHEPERA_TOML.as_bytes(), &ops))?;
    }

    /// An arena with a box and a disc, damaged, read as a file and inside a configuration.
    #[test]
    fn damaged_arenas_are_refused_on_one_line(ops in mutations()) {
        let bytes = mutate(ARENA.as_bytes(), &ops);
        arena(&bytes)?;
        let text = String::from_utf8_lossy(&bytes);
        let inside = DEFAULT_KHEPERA_TOML.replace(
            "[env.arena]\nx = [-6.0, 6.0]                             # m, walls\ny = [-6.0, 6.0]\n",
            &format!("[env.arena]\n{}\n", text.replace("[[obstacle]]", "[[env.arena.obstacle]]")),
        );
        config(inside.as_bytes())?;
    }
}

/// The valid files the properties start from are valid.
#[test]
fn the_valid_files_are_valid() {
    assert!(matches!(
        PolicyFile::from_bytes(fqi_bytes(), Path::new("p.fzq")).unwrap(),
        PolicyFile::Fqi(_)
    ));
    assert!(matches!(
        PolicyFile::from_bytes(fql_bytes(), Path::new("p.fzq")).unwrap(),
        PolicyFile::PointMass(_)
    ));
    assert!(matches!(
        PolicyFile::from_bytes(fql_toml().as_bytes(), Path::new("p.toml")).unwrap(),
        PolicyFile::PointMass(_)
    ));
    TrainConfig::from_toml(DEFAULT_POINTMASS_TOML).unwrap();
    TrainConfig::from_toml(DEFAULT_KHEPERA_TOML).unwrap();
    assert_eq!(Arena::from_toml(ARENA).unwrap().obstacles.len(), 2);
    let inside = DEFAULT_KHEPERA_TOML.replace(
        "[env.arena]\nx = [-6.0, 6.0]                             # m, walls\ny = [-6.0, 6.0]\n",
        &format!(
            "[env.arena]\n{}\n",
            ARENA.replace("[[obstacle]]", "[[env.arena.obstacle]]")
        ),
    );
    assert_ne!(inside, DEFAULT_KHEPERA_TOML);
    let c = TrainConfig::from_toml(&inside).unwrap();
    let EnvConfig::Khepera(k) = c.env else {
        panic!("khepera")
    };
    assert_eq!(k.arena, Arena::from_toml(ARENA).unwrap());
}

/// A header claiming an enormous payload is refused at once, from bytes and from a file,
/// without reserving it (a reservation of 2^62 bytes would abort the test binary); so is a
/// payload whose table claims 2^60 values.
#[test]
fn enormous_lengths_are_refused_without_allocating_them() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.fzq");
    for len in [
        u64::MAX,
        u64::MAX - 23,
        u64::MAX - 24,
        1 << 62,
        1 << 40,
        100,
    ] {
        let mut b = MAGIC.to_vec();
        b.extend_from_slice(&2u32.to_le_bytes());
        b.extend_from_slice(&len.to_le_bytes());
        b.extend_from_slice(&0u32.to_le_bytes());
        b.extend_from_slice(b"abc");
        let start = Instant::now();
        let e = PolicyFile::from_bytes(&b, Path::new("huge.fzq")).unwrap_err();
        assert!(
            matches!(
                e,
                PolicyFileError::Truncated { .. } | PolicyFileError::Malformed { .. }
            ),
            "{e}"
        );
        std::fs::write(&path, &b).unwrap();
        let from_file = PolicyFile::load(&path).unwrap_err().to_string();
        let from_bytes = PolicyFile::from_bytes(&b, &path).unwrap_err().to_string();
        assert_eq!(from_file, from_bytes);
        assert!(!from_file.contains('\n'), "{from_file}");
        assert!(start.elapsed() < SLOW);
    }
    // Regression: a header announcing 2^45 bytes (so the file is decoded as it is read) and
    // a fuzzy Q-iteration payload whose configuration claims 2^40 bytes: the string's buffer
    // was reserved at that length and the process aborted. It grows as the bytes arrive.
    let mut b = MAGIC.to_vec();
    b.extend_from_slice(&2u32.to_le_bytes());
    b.extend_from_slice(&(1u64 << 45).to_le_bytes());
    b.extend_from_slice(&0u32.to_le_bytes());
    b.extend_from_slice(&[0, 0x80, 0x80, 0x80, 0x80, 0x80, 0x20]);
    b.extend_from_slice(b"[env]");
    std::fs::write(&path, &b).unwrap();
    let start = Instant::now();
    let e = PolicyFile::load(&path).unwrap_err();
    assert!(matches!(e, PolicyFileError::Truncated { .. }), "{e}");
    assert_eq!(
        e.to_string(),
        PolicyFile::from_bytes(&b, &path).unwrap_err().to_string()
    );
    assert!(start.elapsed() < SLOW);
    // A fuzzy Q-iteration payload (kind 0) with a valid configuration, then values in single
    // precision (variant 0) claiming 2^60 of them.
    let config = TrainConfig::default().to_toml();
    let mut payload = vec![0u8];
    let mut n = config.len();
    while n >= 0x80 {
        payload.push((n as u8) | 0x80);
        n >>= 7;
    }
    payload.push(n as u8);
    payload.extend_from_slice(config.as_bytes());
    payload.push(0);
    payload.extend_from_slice(&[0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x80, 0x10]);
    let start = Instant::now();
    let e = PolicyFile::from_bytes(&seal(2, &payload), Path::new("huge.fzq")).unwrap_err();
    assert!(matches!(e, PolicyFileError::Malformed { .. }), "{e}");
    assert!(start.elapsed() < SLOW);
}

/// A file with more bytes than its header gives is refused the same way from bytes and from
/// a file (the loader reads one byte past the payload to see it).
#[test]
fn data_after_the_payload_is_refused() {
    let mut b = fqi_bytes().to_vec();
    b.extend_from_slice(b"tail");
    let e = PolicyFile::from_bytes(&b, Path::new("t.fzq"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("data after the end"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.fzq");
    std::fs::write(&path, &b).unwrap();
    let from_file = PolicyFile::load(&path).unwrap_err().to_string();
    assert!(from_file.contains("data after the end"), "{from_file}");
}
