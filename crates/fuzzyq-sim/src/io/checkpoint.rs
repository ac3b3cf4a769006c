//! Checkpoints: the state of a training run between two sweeps (fuzzy Q-iteration) or two
//! episodes (fuzzy Q-learning, VQQL), written atomically so that a run stopped at any moment
//! (Ctrl-C, a kill, a power cut) continues from its last checkpoint to the very policy, byte
//! for byte, an uninterrupted run writes.
//!
//! A checkpoint is a container (`io/container.rs`, the policy file's layout) with the tag `\x89FZQCKP\n` and format
//! version 1; its payload (postcard) holds the run's settings as text and its state. A run
//! continues only under the same settings: [`Checkpoint::check_settings`] names the first
//! setting that differs. The thread count may differ (results do not depend on it), and so
//! may the CPU's kernel instance (every instance gives the same bits).

use std::path::Path;

use fuzzyq_core::solver::{SolverState, SweepRecord};
use serde::{Deserialize, Serialize};

use super::container::{self, Damage, Decode, Decoder, Encoder, Float, Source};
pub use crate::error::CheckpointError;
use crate::learn::fql::FqlState;

/// The magic tag every checkpoint starts with.
pub const MAGIC: [u8; 8] = *b"\x89FZQCKP\n";
/// The format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// The state of a fuzzy Q-iteration run in its precision.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum FqiState<'a> {
    /// Single precision.
    F32(SolverState<'a, f32>),
    /// Double precision.
    F64(SolverState<'a, f64>),
}

impl FqiState<'_> {
    /// Sweeps done.
    #[must_use]
    pub fn sweeps(&self) -> usize {
        match self {
            Self::F32(s) => s.sweeps(),
            Self::F64(s) => s.sweeps(),
        }
    }

    /// A view that borrows the state's buffers ([`SolverState::borrowed`]): what a checkpoint
    /// writes, with no copy of `V`.
    #[must_use]
    pub fn borrowed(&self) -> FqiState<'_> {
        match self {
            Self::F32(s) => FqiState::F32(s.borrowed()),
            Self::F64(s) => FqiState::F64(s.borrowed()),
        }
    }

    /// An owned copy.
    #[must_use]
    pub fn into_owned(self) -> FqiState<'static> {
        match self {
            Self::F32(s) => FqiState::F32(s.into_owned()),
            Self::F64(s) => FqiState::F64(s.into_owned()),
        }
    }
}

/// What a checkpoint continues.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum RunState<'a> {
    /// Fuzzy Q-iteration, after a sweep.
    Fqi(FqiState<'a>),
    /// Fuzzy Q-learning or VQQL, after an episode.
    Fql(FqlState),
}

impl RunState<'_> {
    /// `"sweep 12"` or `"episode 340"`: how far the run got, for messages.
    #[must_use]
    pub fn progress(&self) -> String {
        match self {
            Self::Fqi(s) => format!("sweep {}", s.sweeps()),
            Self::Fql(s) => format!("episode {}", s.episodes()),
        }
    }
}

/// A run's settings and its state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Checkpoint<'a> {
    /// Everything that decides the run's result, as text (the caller's choice, compared line
    /// by line by [`check_settings`](Self::check_settings)).
    pub settings: std::borrow::Cow<'a, str>,
    /// The state.
    pub state: RunState<'a>,
}

impl Checkpoint<'_> {
    /// The file's bytes.
    #[must_use]
    pub fn to_bytes(&self) -> Vec<u8> {
        // Postcard cannot fail on these types (no maps, no unsized sequences).
        container::write_encoded(
            std::io::Cursor::new(Vec::new()),
            &MAGIC,
            FORMAT_VERSION,
            |e| self.encode(e),
        )
        .map(std::io::Cursor::into_inner)
        .unwrap_or_default()
    }

    /// The payload as its derived serialisation encodes it, `V` and the policy in bulk
    /// ([`Encoder`]): `postcard::to_stdvec(self)`'s bytes, as
    /// `written_as_serde_encodes_it` checks.
    fn encode<W: std::io::Write>(&self, e: &mut Encoder<W>) -> std::io::Result<()> {
        e.value(&self.settings)?;
        let RunState::Fqi(fqi) = &self.state else {
            return e.value(&self.state);
        };
        e.variant(0)?;
        match fqi {
            FqiState::F32(s) => {
                e.variant(0)?;
                encode_state(s, e)
            }
            FqiState::F64(s) => {
                e.variant(1)?;
                encode_state(s, e)
            }
        }
    }

    /// Writes the checkpoint atomically (a temporary file beside `path`, then a rename),
    /// encoding it as it goes: [`Self::to_bytes`]'s bytes, never held whole (a checkpoint of
    /// three point masses on the paper's cores holds 66 GB of `V` and policy).
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        super::write_atomically_with(path, |file| {
            container::write_encoded(file, &MAGIC, FORMAT_VERSION, |e| self.encode(e)).map(|_| ())
        })
        .map_err(|error| CheckpointError::Write {
            path: path.to_path_buf(),
            error,
        })
    }

    /// Refuses to continue under `settings` unless they are the checkpoint's, naming the
    /// first line that differs.
    pub fn check_settings(&self, settings: &str, path: &Path) -> Result<(), CheckpointError> {
        if self.settings == settings {
            return Ok(());
        }
        let (mut here, mut there) = (settings.lines(), self.settings.lines());
        let difference = loop {
            match (here.next(), there.next()) {
                (Some(a), Some(b)) if a == b => {}
                (a, b) => {
                    let show = |l: Option<&str>| match l {
                        None => "nothing".into(),
                        Some("") => "an empty line".into(),
                        Some(l) => format!("`{}`", l.trim()),
                    };
                    break format!("{} here, {} there", show(a), show(b));
                }
            }
        };
        Err(CheckpointError::Settings {
            path: path.to_path_buf(),
            difference,
        })
    }
}

impl Checkpoint<'static> {
    /// Reads and checks the checkpoint at `path` (read once: a pipe works; never more than
    /// its header announces). A payload of 1 MiB or more is decoded as it is read, so that
    /// the state is held once, not also as the file's bytes; the checks and their messages
    /// are [`Self::from_bytes`]'s.
    pub fn load(path: &Path) -> Result<Self, CheckpointError> {
        Self::load_streaming_from(path, container::STREAM_FROM)
    }

    /// [`Self::load`], decoding a payload of at least `stream_from` bytes as it is read.
    fn load_streaming_from(path: &Path, stream_from: u64) -> Result<Self, CheckpointError> {
        let read = |error| CheckpointError::Read {
            path: path.to_path_buf(),
            error,
        };
        match container::read(path, &MAGIC, Some(stream_from)).map_err(read)? {
            container::Read::Container(bytes) => Self::from_bytes(&bytes, path),
            container::Read::Large(header, file) => Self::from_stream(&header, file, path),
            container::Read::Other(head, _) => Err(CheckpointError::NotACheckpoint {
                path: path.to_path_buf(),
                policy: head.starts_with(&super::policy_file::MAGIC),
            }),
        }
    }

    /// The checkpoint whose container starts with `header` and whose payload is the rest of
    /// `file`, decoded as it is read. The damage is found in [`Self::from_bytes`]'s order
    /// (length, checksum, version, content), so a file gives the same error either way.
    fn from_stream(
        header: &[u8; container::HEADER_LEN],
        file: std::fs::File,
        path: &Path,
    ) -> Result<Self, CheckpointError> {
        use container::Streamed;
        let (version, len, crc) = container::fields(header);
        let error = |e| match e {
            Streamed::Io(error) => CheckpointError::Read {
                path: path.to_path_buf(),
                error,
            },
            Streamed::Damage(d) => damaged(path, d),
            Streamed::Content(reason) => {
                damaged_because(path, format!("cannot be decoded: {reason}"))
            }
        };
        if version != FORMAT_VERSION {
            // Another version's content is not ours to decode, but its damage comes first:
            // the payload is read through as the empty value, which leaves all of it over.
            return match container::decode_streamed::<()>(file, len, crc) {
                Ok(()) | Err(Streamed::Content(_)) => Err(wrong_version(path, version)),
                Err(e) => Err(error(e)),
            };
        }
        container::decode_streamed_as(file, len, crc).map_err(error)
    }

    /// Decodes a checkpoint's bytes (`path` names it in errors).
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, CheckpointError> {
        if !bytes.starts_with(&MAGIC) {
            return Err(CheckpointError::NotACheckpoint {
                path: path.to_path_buf(),
                policy: bytes.starts_with(&super::policy_file::MAGIC),
            });
        }
        let (version, payload) = container::split(bytes).map_err(|d| damaged(path, d))?;
        if version != FORMAT_VERSION {
            return Err(wrong_version(path, version));
        }
        container::decode_payload(payload)
            .map_err(|e| damaged_because(path, format!("cannot be decoded: {e}")))
    }
}

/// The error of a checkpoint at `path` whose container has `damage`.
fn damaged(path: &Path, damage: Damage) -> CheckpointError {
    damaged_because(
        path,
        match damage {
            Damage::Truncated { found, expected } => {
                format!("is truncated ({found} of {expected} bytes)")
            }
            Damage::Trailing(n) => format!("has {n} bytes after its content"),
            Damage::Checksum => "is corrupted (checksum mismatch)".into(),
        },
    )
}

/// The error of a checkpoint at `path` of another format `version`.
fn wrong_version(path: &Path, version: u32) -> CheckpointError {
    damaged_because(
        path,
        format!("has format version {version}; this build reads version {FORMAT_VERSION}"),
    )
}

/// A solver's state as its derived serialisation encodes it (its fields in order), `V`, the
/// `V` before it and the policy in bulk.
fn encode_state<T: Float, W: std::io::Write>(
    s: &SolverState<'_, T>,
    e: &mut Encoder<W>,
) -> std::io::Result<()> {
    e.value(&s.scheme)?;
    e.floats(&s.v)?;
    e.floats(&s.v_prev)?;
    e.u32s(&s.policy)?;
    e.value(&(
        s.shift,
        s.evaluations_left,
        s.evaluation_tolerance,
        s.final_delta,
        s.sweep_seconds,
        s.evaluation_seconds,
        &s.records,
    ))
}

impl Decode for Checkpoint<'static> {
    /// The payload as its derived deserialisation decodes it, `V`, the `V` before it and the
    /// policy in bulk (the mirror of [`Checkpoint::encode`]; `read_as_serde_decodes_it`).
    fn decode<S: Source>(d: &mut Decoder<S>) -> postcard::Result<Self> {
        let settings: String = d.value()?;
        let state = match d.variant()? {
            0 => RunState::Fqi(match d.variant()? {
                0 => FqiState::F32(decode_state(d)?),
                1 => FqiState::F64(decode_state(d)?),
                _ => return Err(postcard::Error::DeserializeBadEnum),
            }),
            1 => RunState::Fql(d.value()?),
            _ => return Err(postcard::Error::DeserializeBadEnum),
        };
        Ok(Checkpoint {
            settings: settings.into(),
            state,
        })
    }
}

/// A solver's state as [`encode_state`] writes it.
fn decode_state<T: Float, S: Source>(
    d: &mut Decoder<S>,
) -> postcard::Result<SolverState<'static, T>> {
    let scheme = d.value()?;
    let (v, v_prev, policy) = (d.floats()?, d.floats()?, d.u32s()?);
    // The fields after the arrays, as `encode_state` writes them: one tuple.
    type Tail = (f64, usize, f64, f64, f64, f64, Vec<SweepRecord>);
    let (shift, left, tolerance, delta, sweep_s, eval_s, records): Tail = d.value()?;
    Ok(SolverState {
        scheme,
        v: v.into(),
        v_prev: v_prev.into(),
        policy: policy.into(),
        shift,
        evaluations_left: left,
        evaluation_tolerance: tolerance,
        final_delta: delta,
        sweep_seconds: sweep_s,
        evaluation_seconds: eval_s,
        records: records.into(),
    })
}

/// The error of a damaged checkpoint at `path`: it `reason` (`"is truncated (...)"`).
fn damaged_because(path: &Path, reason: String) -> CheckpointError {
    CheckpointError::Damaged {
        path: path.to_path_buf(),
        reason,
    }
}

#[cfg(test)]
mod tests {
    use std::borrow::Cow;

    use fuzzyq_core::solver::Scheme;

    use super::*;

    fn checkpoint() -> Checkpoint<'static> {
        Checkpoint {
            settings: Cow::Borrowed("gamma = 0.9\n"),
            state: RunState::Fqi(FqiState::F32(SolverState {
                scheme: Scheme::Value,
                v: Cow::Owned(vec![1.0, 2.0]),
                v_prev: Cow::Owned(vec![0.5, 1.5]),
                policy: Cow::Owned(Vec::new()),
                shift: 0.0,
                evaluations_left: 0,
                evaluation_tolerance: 0.0,
                final_delta: 0.5,
                sweep_seconds: 0.0,
                evaluation_seconds: 0.0,
                records: Cow::Owned(Vec::new()),
            })),
        }
    }

    /// `bytes` decoded in memory, after checking that a file of them decoded as it is read
    /// gives the same checkpoint or the same error.
    fn decode(bytes: &[u8]) -> Result<Checkpoint<'static>, CheckpointError> {
        container::read_both_ways(bytes, Checkpoint::from_bytes, |path| {
            Checkpoint::load_streaming_from(path, 0)
        })
    }

    /// Saved as it is encoded: the bytes of `to_bytes`, which both ways of reading give back.
    #[test]
    fn saved_as_encoded_and_read_back_either_way() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.ckpt");
        checkpoint().save(&path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes, checkpoint().to_bytes());
        assert_eq!(decode(&bytes).unwrap(), checkpoint());
        assert_eq!(Checkpoint::load(&path).unwrap(), checkpoint());
    }

    /// Checkpoints of single and double precision, policies of one to five varint bytes,
    /// arrays longer than the encoder's buffer, and records.
    fn checkpoints() -> Vec<Checkpoint<'static>> {
        use fuzzyq_core::solver::{Delta, SweepRecord};

        let n = 70_000;
        let policy: Vec<u32> = (0..n as u32)
            .map(|i| i.wrapping_mul(2_654_435_761) >> (i % 32))
            .collect();
        let records = vec![
            SweepRecord {
                sweep: 2,
                delta: Delta {
                    lower: 0.5,
                    upper: 0.75,
                },
                delta_v: 0.7,
                seconds: 1.25,
                extrapolated: true,
                evaluation: false,
            };
            3
        ];
        let FqiState::F32(base) = (match checkpoint().state {
            RunState::Fqi(s) => s,
            RunState::Fql(_) => unreachable!(),
        }) else {
            unreachable!()
        };
        let narrow = SolverState {
            scheme: Scheme::ModifiedPolicy,
            v: Cow::Owned((0..n).map(|i| (i as f32).sin()).collect()),
            v_prev: Cow::Owned(vec![2.5; 3]),
            policy: Cow::Owned(policy.clone()),
            shift: 0.25,
            evaluations_left: 4,
            records: Cow::Owned(records),
            ..base
        };
        let wide = SolverState {
            scheme: narrow.scheme,
            v: Cow::Owned((0..n).map(|i| (i as f64).cos()).collect()),
            v_prev: Cow::Owned(Vec::new()),
            policy: Cow::Owned(policy),
            shift: 1.0,
            evaluations_left: 1,
            evaluation_tolerance: 0.125,
            final_delta: 3.0,
            sweep_seconds: 7.5,
            evaluation_seconds: 1.5,
            records: narrow.records.clone(),
        };
        [
            RunState::Fqi(FqiState::F32(narrow)),
            RunState::Fqi(FqiState::F64(wide)),
            checkpoint().state,
        ]
        .into_iter()
        .map(|state| Checkpoint {
            settings: Cow::Borrowed("gamma = 0.9\nxi = 0.05\n"),
            state,
        })
        .collect()
    }

    /// `V`, the `V` before it and the policy written in bulk give serde's bytes
    /// ([`checkpoints`]).
    #[test]
    fn written_as_serde_encodes_it() {
        for c in checkpoints() {
            let serde = container::encode_postcard(&MAGIC, FORMAT_VERSION, &c).unwrap();
            assert_eq!(c.to_bytes(), serde, "{}", c.state.progress());
            assert_eq!(decode(&serde).unwrap(), c);
        }
    }

    /// Read in bulk ([`Decode`]), every checkpoint ([`checkpoints`]) gives serde's state,
    /// and a damaged one serde's error (the checks: `container::assert_decoded_as_serde`).
    #[test]
    fn read_as_serde_decodes_it() {
        for (k, c) in checkpoints().iter().enumerate() {
            let bytes = c.to_bytes();
            container::assert_decoded_as_serde::<Checkpoint<'static>>(
                &bytes[container::HEADER_LEN..],
                &format!("checkpoint {k}"),
            );
        }
    }

    /// Damage gives the same one-line error whether the file is decoded in memory or as it
    /// is read (checkpoints of 1 MiB or more).
    #[test]
    fn damage_is_named_alike_in_memory_and_as_read() {
        let bytes = checkpoint().to_bytes();
        let reason = |bytes: &[u8]| match decode(bytes).unwrap_err() {
            CheckpointError::Damaged { reason, .. } => reason,
            e => panic!("{e}"),
        };
        let n = bytes.len();
        assert_eq!(
            reason(&bytes[..n - 3]),
            format!("is truncated ({} of {n} bytes)", n - 3)
        );
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(reason(&longer), "has 1 bytes after its content");
        let mut flipped = bytes.clone();
        flipped[n - 1] ^= 1;
        assert_eq!(reason(&flipped), "is corrupted (checksum mismatch)");
        let mut v2 = bytes.clone();
        v2[8] = 2;
        assert_eq!(
            reason(&v2),
            "has format version 2; this build reads version 1"
        );
        // Another version's damage is named first, as in memory.
        v2[n - 1] ^= 1;
        assert_eq!(reason(&v2), "is corrupted (checksum mismatch)");
        let payload = &bytes[container::HEADER_LEN..];
        let wrong = container::encode(&MAGIC, FORMAT_VERSION, &payload[..payload.len() - 1]);
        assert!(
            reason(&wrong).starts_with("cannot be decoded: "),
            "{}",
            reason(&wrong)
        );
        let mut huge = bytes[..container::HEADER_LEN].to_vec();
        huge[12..20].copy_from_slice(&u64::MAX.to_le_bytes());
        assert_eq!(
            reason(&huge),
            format!("is truncated (24 of {} bytes)", u64::MAX)
        );
    }

    /// A header announcing a terabyte and a settings string claiming as much, in a file of a
    /// few bytes: refused as truncated, nothing allocated ahead (it aborted the process).
    #[test]
    fn a_string_longer_than_the_file_allocates_nothing_ahead() {
        let mut file = MAGIC.to_vec();
        file.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        file.extend_from_slice(&(1u64 << 45).to_le_bytes());
        file.extend_from_slice(&0u32.to_le_bytes());
        // The settings' length, 2^40, as a postcard varint.
        file.extend_from_slice(&[0x80, 0x80, 0x80, 0x80, 0x80, 0x20]);
        file.extend_from_slice(b"gamma");
        let e = decode(&file).unwrap_err().to_string();
        assert!(e.contains("is truncated (35 of"), "{e}");
    }

    /// Regression (issue 49): bytes appended inside the checksummed payload were ignored.
    #[test]
    fn a_payload_with_bytes_after_its_content_is_refused() {
        let bytes = checkpoint().to_bytes();
        let path = Path::new("c.ckpt");
        assert_eq!(Checkpoint::from_bytes(&bytes, path).unwrap(), checkpoint());
        let mut payload = bytes[container::HEADER_LEN..].to_vec();
        payload.push(0);
        let longer = container::encode(&MAGIC, FORMAT_VERSION, &payload);
        let e = Checkpoint::from_bytes(&longer, path)
            .unwrap_err()
            .to_string();
        assert!(e.contains("1 bytes after its content"), "{e}");
    }
}
