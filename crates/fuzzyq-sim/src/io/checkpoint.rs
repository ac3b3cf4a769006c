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

use fuzzyq_core::solver::SolverState;
use serde::{Deserialize, Serialize};

use super::container::{self, Damage};
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
        container::encode_postcard(&MAGIC, FORMAT_VERSION, self).unwrap_or_default()
    }

    /// Writes the checkpoint atomically (a temporary file beside `path`, then a rename).
    pub fn save(&self, path: &Path) -> Result<(), CheckpointError> {
        super::write_atomically(path, &self.to_bytes()).map_err(|error| CheckpointError::Write {
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
    /// its header announces).
    pub fn load(path: &Path) -> Result<Self, CheckpointError> {
        let read = |error| CheckpointError::Read {
            path: path.to_path_buf(),
            error,
        };
        match container::read(path, &MAGIC, None).map_err(read)? {
            container::Read::Container(bytes) => Self::from_bytes(&bytes, path),
            container::Read::Large(..) => unreachable!("not asked to stream"),
            container::Read::Other(head, _) => Err(CheckpointError::NotACheckpoint {
                path: path.to_path_buf(),
                policy: head.starts_with(&super::policy_file::MAGIC),
            }),
        }
    }

    /// Decodes a checkpoint's bytes (`path` names it in errors).
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, CheckpointError> {
        let damaged = |reason: String| CheckpointError::Damaged {
            path: path.to_path_buf(),
            reason,
        };
        if !bytes.starts_with(&MAGIC) {
            return Err(CheckpointError::NotACheckpoint {
                path: path.to_path_buf(),
                policy: bytes.starts_with(&super::policy_file::MAGIC),
            });
        }
        let (version, payload) = container::split(bytes).map_err(|d| {
            damaged(match d {
                Damage::Truncated { found, expected } => {
                    format!("is truncated ({found} of {expected} bytes)")
                }
                Damage::Trailing(n) => format!("has {n} bytes after its content"),
                Damage::Checksum => "is corrupted (checksum mismatch)".into(),
            })
        })?;
        if version != FORMAT_VERSION {
            return Err(damaged(format!(
                "has format version {version}; this build reads version {FORMAT_VERSION}"
            )));
        }
        container::decode_postcard(payload).map_err(|e| damaged(format!("cannot be decoded: {e}")))
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
