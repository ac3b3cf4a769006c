//! The policy file: everything needed to act, written atomically.
//!
//! # Layout (little-endian)
//! | bytes | content |
//! |---|---|
//! | 8 | magic tag `\x89FUZZYQ\n` (the high byte catches 7-bit and text-mode mangling) |
//! | 4 | format version, `u32` (currently 1) |
//! | 8 | payload length in bytes, `u64` |
//! | 4 | CRC-32 of the payload, `u32` |
//! | n | payload: a [`PolicyArtifact`] in postcard encoding |
//!
//! The payload holds the training configuration (model parameters, grid, solver settings),
//! `V` per core, the per-core greedy joint actions and the training summary. A file is written
//! to a temporary file in the destination's directory, flushed and renamed over the
//! destination, so a crash or a full disk never leaves a half-written policy. Reading checks
//! the tag, version, length, checksum and the payload's consistency, and names what is wrong.

use std::io::Write;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::PolicyFileError;
use crate::io::config::{Precision, TrainConfig};

/// The magic tag every policy file starts with.
pub const MAGIC: [u8; 8] = *b"\x89FUZZYQ\n";
/// The format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;
const HEADER_LEN: usize = 8 + 4 + 8 + 4;

/// Per-core values in the solver's precision.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Values {
    /// Single precision.
    F32(Vec<f32>),
    /// Double precision.
    F64(Vec<f64>),
}

impl Values {
    /// Number of values.
    #[must_use]
    pub fn len(&self) -> usize {
        match self {
            Self::F32(v) => v.len(),
            Self::F64(v) => v.len(),
        }
    }

    /// Whether there are no values.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The precision.
    #[must_use]
    pub fn precision(&self) -> Precision {
        match self {
            Self::F32(_) => Precision::F32,
            Self::F64(_) => Precision::F64,
        }
    }

    fn all_finite(&self) -> bool {
        match self {
            Self::F32(v) => v.iter().all(|x| x.is_finite()),
            Self::F64(v) => v.iter().all(|x| x.is_finite()),
        }
    }
}

/// How training went.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainSummary {
    /// Sweeps performed.
    pub sweeps: usize,
    /// Whether the stopping rule was met.
    pub converged: bool,
    /// The exact change of the last sweep.
    pub final_delta: f64,
    /// `(lower, upper)` bounds of every sweep's change (equal when exact).
    pub deltas: Vec<(f64, f64)>,
    /// The sweeps (from 1) that started from an extrapolated `V` (not tested against `xi`).
    pub extrapolated: Vec<usize>,
    /// Wall-clock seconds of the solve.
    pub seconds: f64,
    /// The a-priori sweep bound (eq 37).
    pub sweep_bound: usize,
    /// `max |rho|` over cores and joint actions.
    pub reward_bound: f64,
    /// Backup path used: `"block"` or `"generic"`.
    pub backup: String,
    /// Kernel instance: `"avx512"`, `"avx2"`, `"scalar"` or `"generic"`.
    pub kernel: String,
    /// Multiply-adds of one sweep on the block path.
    pub multiply_adds_per_sweep: Option<f64>,
    /// Seconds spent in sweeps (the solve minus its set-up and the final passes).
    pub sweep_seconds: f64,
    /// The fuzzyq version that trained it.
    pub fuzzyq_version: String,
}

impl TrainSummary {
    /// The summary of a solver run.
    pub fn from_solution<T>(s: &fuzzyq_core::solver::Solution<T>) -> Self {
        Self {
            sweeps: s.sweeps.len(),
            converged: s.converged(),
            final_delta: s.final_delta,
            deltas: s
                .sweeps
                .iter()
                .map(|r| (r.delta.lower, r.delta.upper))
                .collect(),
            extrapolated: s
                .sweeps
                .iter()
                .filter(|r| r.extrapolated)
                .map(|r| r.sweep)
                .collect(),
            seconds: s.seconds,
            sweep_bound: s.bound,
            reward_bound: s.reward_bound,
            backup: match s.path {
                fuzzyq_core::solver::BackupPath::Generic => "generic",
                _ => "block",
            }
            .into(),
            kernel: s.kernel.into(),
            multiply_adds_per_sweep: s.multiply_adds_per_sweep,
            sweep_seconds: s.sweep_seconds,
            fuzzyq_version: env!("CARGO_PKG_VERSION").into(),
        }
    }
}

/// A trained policy.
#[derive(Clone, Debug, PartialEq)]
pub struct PolicyArtifact {
    /// The configuration it was trained with.
    pub config: TrainConfig,
    /// `V` per core, row-major grid order.
    pub values: Values,
    /// Greedy joint action per core, row-major grid order.
    pub greedy: Vec<u32>,
    /// How training went.
    pub summary: TrainSummary,
}

/// The encoded form: the configuration travels as its TOML text (postcard cannot encode the
/// config's internally tagged enums, and TOML keeps it readable and stable across versions).
#[derive(Serialize, Deserialize)]
struct Payload {
    config_toml: String,
    values: Values,
    greedy: Vec<u32>,
    summary: TrainSummary,
}

impl PolicyArtifact {
    /// Checks the artifact's internal consistency.
    pub fn check(&self) -> Result<(), String> {
        self.config.validate().map_err(|e| e.to_string())?;
        let n = self.config.n_cores();
        if self.values.len() != n {
            return Err(format!(
                "{} values for a grid of {n} cores",
                self.values.len()
            ));
        }
        if self.greedy.len() != n {
            return Err(format!(
                "{} greedy actions for a grid of {n} cores",
                self.greedy.len()
            ));
        }
        if self.values.precision() != self.config.solver.precision {
            return Err("values are not in the configured precision".into());
        }
        if !self.values.all_finite() {
            return Err("a value is not a finite number".into());
        }
        let m = self.n_joint_actions();
        if let Some(u) = self.greedy.iter().find(|&&u| u as usize >= m) {
            return Err(format!("greedy action {u} is out of range 0..{m}"));
        }
        Ok(())
    }

    /// Number of joint actions of the configured environment.
    #[must_use]
    pub fn n_joint_actions(&self) -> usize {
        match &self.config.env {
            crate::io::config::EnvConfig::Pointmass(p) => {
                p.force_levels.len().pow(2 * p.agents as u32)
            }
            crate::io::config::EnvConfig::Khepera(k) => {
                crate::model::khepera::N_ACTIONS.pow(k.agents as u32)
            }
            crate::io::config::EnvConfig::Dcmotor(c) => c.actions.len(),
            crate::io::config::EnvConfig::Pendulum(c) => c.actions.len(),
            crate::io::config::EnvConfig::Carhill(c) => c.actions.len(),
            crate::io::config::EnvConfig::Arm(c) => c.actions.len().pow(2),
        }
    }

    /// Encodes the artifact with its header.
    #[must_use]
    pub fn to_bytes(&self) -> Vec<u8> {
        let payload = postcard::to_stdvec(&Payload {
            config_toml: self.config.to_toml(),
            values: self.values.clone(),
            greedy: self.greedy.clone(),
            summary: self.summary.clone(),
        })
        .expect("an artifact always serialises");
        let mut out = Vec::with_capacity(HEADER_LEN + payload.len());
        out.extend_from_slice(&MAGIC);
        out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
        out.extend_from_slice(&crc32fast::hash(&payload).to_le_bytes());
        out.extend_from_slice(&payload);
        out
    }

    /// Decodes and checks bytes read from `path` (the path only names the file in errors).
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, PolicyFileError> {
        let path = path.to_path_buf();
        let magic_len = MAGIC.len().min(bytes.len());
        if bytes[..magic_len] != MAGIC[..magic_len] || bytes.is_empty() {
            return Err(PolicyFileError::NotAPolicy { path });
        }
        if bytes.len() < HEADER_LEN {
            return Err(PolicyFileError::Truncated {
                path,
                found: bytes.len() as u64,
                expected: HEADER_LEN as u64,
            });
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        if version != FORMAT_VERSION {
            return Err(PolicyFileError::Version {
                path,
                found: version,
                supported: FORMAT_VERSION,
            });
        }
        let len = u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes"));
        let crc = u32::from_le_bytes(bytes[20..24].try_into().expect("4 bytes"));
        let expected = HEADER_LEN as u64 + len;
        if (bytes.len() as u64) < expected {
            return Err(PolicyFileError::Truncated {
                path,
                found: bytes.len() as u64,
                expected,
            });
        }
        if (bytes.len() as u64) > expected {
            return Err(PolicyFileError::Malformed {
                path,
                reason: format!("{} bytes after the payload", bytes.len() as u64 - expected),
            });
        }
        let payload = &bytes[HEADER_LEN..];
        if crc32fast::hash(payload) != crc {
            return Err(PolicyFileError::Checksum { path });
        }
        let malformed = |reason: String| PolicyFileError::Malformed {
            path: path.clone(),
            reason,
        };
        let p: Payload = postcard::from_bytes(payload).map_err(|e| malformed(e.to_string()))?;
        let config = TrainConfig::from_toml(&p.config_toml)
            .map_err(|e| malformed(format!("its configuration: {e}")))?;
        let artifact = Self {
            config,
            values: p.values,
            greedy: p.greedy,
            summary: p.summary,
        };
        artifact
            .check()
            .map_err(|reason| PolicyFileError::Malformed { path, reason })?;
        Ok(artifact)
    }

    /// Reads and checks a policy file.
    pub fn load(path: &Path) -> Result<Self, PolicyFileError> {
        let bytes = std::fs::read(path).map_err(|source| PolicyFileError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        Self::from_bytes(&bytes, path)
    }

    /// Writes the policy file atomically (temporary file in the same directory, then rename).
    pub fn save(&self, path: &Path) -> Result<(), PolicyFileError> {
        write_atomically(path, &self.to_bytes()).map_err(|source| PolicyFileError::Write {
            path: path.to_path_buf(),
            source,
        })
    }
}

/// Writes `value` as TOML text into `path` atomically (a policy file learned from samples);
/// `what` names the file kind in a serialisation error.
pub(crate) fn save_toml<T: Serialize>(
    value: &T,
    path: &Path,
    what: &str,
) -> Result<(), PolicyFileError> {
    let text = toml::to_string(value).map_err(|e| PolicyFileError::Malformed {
        path: path.to_path_buf(),
        reason: format!("{what}: {e}"),
    })?;
    write_atomically(path, text.as_bytes()).map_err(|source| PolicyFileError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// Reads a TOML file written by [`save_toml`] and checks it with `validate`; every error
/// names the file.
pub(crate) fn load_toml<T: serde::de::DeserializeOwned>(
    path: &Path,
    validate: impl FnOnce(&T) -> Result<(), String>,
) -> Result<T, PolicyFileError> {
    let malformed = |reason: String| PolicyFileError::Malformed {
        path: path.to_path_buf(),
        reason,
    };
    let bytes = std::fs::read(path).map_err(|source| PolicyFileError::Read {
        path: path.to_path_buf(),
        source,
    })?;
    let text =
        std::str::from_utf8(&bytes).map_err(|e| malformed(format!("not UTF-8 text: {e}")))?;
    let value: T =
        toml::from_str(text).map_err(|e| malformed(e.message().trim_end().to_string()))?;
    validate(&value).map_err(malformed)?;
    Ok(value)
}

/// Writes `bytes` to `path` through a temporary file in the same directory and a rename, so
/// the destination holds either its old content or all of the new.
pub fn write_atomically(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let mut tmp = temp_file_beside(path, ".tmp")?;
    tmp.write_all(bytes)?;
    tmp.as_file().sync_all()?;
    tmp.persist(path).map_err(|e| e.error)?;
    Ok(())
}

/// A temporary file in `path`'s directory (so that a rename onto `path` is atomic), named with
/// `suffix`, readable like a freshly created file (mode 0644 on Unix rather than the 0600 of
/// temporary files). Dropped without `persist`, it is removed.
pub fn temp_file_beside(path: &Path, suffix: &str) -> std::io::Result<tempfile::NamedTempFile> {
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    let mut b = tempfile::Builder::new();
    b.prefix(".fuzzyq-").suffix(suffix);
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        b.permissions(std::fs::Permissions::from_mode(0o644));
    }
    b.tempfile_in(dir)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::config::{GridConfig, TrainConfig};

    fn tiny() -> PolicyArtifact {
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
            summary: TrainSummary {
                sweeps: 3,
                converged: true,
                final_delta: 0.01,
                deltas: vec![(5.0, 5.0), (0.1, 0.2), (0.01, 0.01)],
                extrapolated: vec![2],
                seconds: 0.5,
                sweep_bound: 200,
                reward_bound: 5.0,
                backup: "block".into(),
                kernel: "scalar".into(),
                multiply_adds_per_sweep: Some(1e6),
                sweep_seconds: 0.4,
                fuzzyq_version: "test".into(),
            },
        }
    }

    #[test]
    fn round_trips_and_refuses_damage() {
        let a = tiny();
        let bytes = a.to_bytes();
        let p = Path::new("p.fzq");
        assert_eq!(PolicyArtifact::from_bytes(&bytes, p).unwrap(), a);

        let e = PolicyArtifact::from_bytes(&bytes[..bytes.len() - 10], p).unwrap_err();
        assert!(matches!(e, PolicyFileError::Truncated { .. }), "{e}");
        let e = PolicyArtifact::from_bytes(&bytes[..5], p).unwrap_err();
        assert!(matches!(e, PolicyFileError::Truncated { .. }), "{e}");
        let e = PolicyArtifact::from_bytes(b"[env]\nkind = 1\n", p).unwrap_err();
        assert!(matches!(e, PolicyFileError::NotAPolicy { .. }), "{e}");
        let e = PolicyArtifact::from_bytes(b"", p).unwrap_err();
        assert!(matches!(e, PolicyFileError::NotAPolicy { .. }), "{e}");

        let mut flipped = bytes.clone();
        let last = flipped.len() - 1;
        flipped[last] ^= 1;
        let e = PolicyArtifact::from_bytes(&flipped, p).unwrap_err();
        assert!(matches!(e, PolicyFileError::Checksum { .. }), "{e}");

        let mut v2 = bytes.clone();
        v2[8] = 2;
        let e = PolicyArtifact::from_bytes(&v2, p).unwrap_err();
        assert!(
            matches!(e, PolicyFileError::Version { found: 2, .. }),
            "{e}"
        );

        let mut bad = a.clone();
        bad.greedy[0] = 625;
        let e = PolicyArtifact::from_bytes(&bad.to_bytes(), p).unwrap_err();
        assert!(e.to_string().contains("out of range"), "{e}");
    }

    #[test]
    fn save_is_atomic_and_loads() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("policy.fzq");
        let a = tiny();
        a.save(&path).unwrap();
        assert_eq!(PolicyArtifact::load(&path).unwrap(), a);
        // Only the destination remains: no temporary files.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
        let missing = dir.path().join("no/such/dir/p.fzq");
        assert!(a.save(&missing).is_err());
        assert!(!missing.exists());
    }
}
