//! Errors of the sim crate: one enum per concern, each message one line naming what is wrong.

use std::path::PathBuf;

use fuzzyq_core::solver::SolveError;
use fuzzyq_core::{EvalError, PartitionError};

/// An invalid configuration: a field out of range, a malformed file, a wrong combination.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// A field has an invalid value.
    #[error("{field}: {reason}")]
    Invalid {
        /// The field, as written in a config file (`env.mass`).
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// The TOML text does not parse or does not match the schema.
    #[error("{0}")]
    Parse(String),
}

impl ConfigError {
    /// An invalid field.
    pub fn invalid(field: impl Into<String>, reason: impl Into<String>) -> Self {
        Self::Invalid {
            field: field.into(),
            reason: reason.into(),
        }
    }
}

/// A policy file that cannot be read or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum PolicyFileError {
    /// Reading failed.
    #[error("cannot read {}: {error}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error (in the message, and not also a source: a printed chain would
        /// repeat it).
        error: std::io::Error,
    },
    /// Writing failed (nothing was left at the destination).
    #[error("cannot write {}: {error}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error (in the message only, as for `Read`).
        error: std::io::Error,
    },
    /// The file does not start with the policy magic tag.
    #[error("{} is not a fuzzyq policy file", path.display())]
    NotAPolicy {
        /// The file.
        path: PathBuf,
    },
    /// The file was written by an incompatible format version.
    #[error(
        "{} has policy format version {found}; this build reads versions 1 to {supported}",
        path.display()
    )]
    Version {
        /// The file.
        path: PathBuf,
        /// Its version.
        found: u32,
        /// The newest version this build reads.
        supported: u32,
    },
    /// The file is shorter than its header says.
    #[error("{} is truncated ({found} of {expected} bytes)", path.display())]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Bytes present.
        found: u64,
        /// Bytes expected.
        expected: u64,
    },
    /// The payload does not match its checksum.
    #[error("{} is corrupted (checksum mismatch)", path.display())]
    Checksum {
        /// The file.
        path: PathBuf,
    },
    /// The payload does not decode or is inconsistent.
    #[error("{} is malformed: {reason}", path.display())]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
}

/// Any failure of training or acting.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SimError {
    /// Invalid configuration.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The solver refused or stopped.
    #[error(transparent)]
    Solve(#[from] SolveError),
    /// A state, action or buffer was rejected.
    #[error(transparent)]
    Eval(#[from] EvalError),
    /// The grid is invalid (the message includes the partition's: it is not also a source,
    /// which would repeat it in a printed chain).
    #[error("grid: {0}")]
    Grid(PartitionError),
    /// A policy file problem.
    #[error(transparent)]
    PolicyFile(#[from] PolicyFileError),
    /// A run would need more memory than its limit.
    #[error(
        "this run needs about {needed_gb:.2} GB of memory for {what}, more than the limit of \
         {limit_gb:.2} GB ({limit_source})"
    )]
    Memory {
        /// The estimate.
        needed_gb: f64,
        /// The limit.
        limit_gb: f64,
        /// What needs the memory.
        what: String,
        /// Where the limit comes from.
        limit_source: String,
    },
    /// A checkpoint problem.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// The GPU path refused the run or failed (`solver.device = "gpu"`).
    #[error(transparent)]
    Gpu(fuzzyq_gpu::GpuError),
}

impl From<fuzzyq_gpu::GpuError> for SimError {
    fn from(e: fuzzyq_gpu::GpuError) -> Self {
        match e {
            fuzzyq_gpu::GpuError::Solve(s) => Self::Solve(s),
            e => Self::Gpu(e),
        }
    }
}

/// Returns `Err(ConfigError::invalid(field, reason).into())` from the enclosing function
/// unless `ok` holds. `field` and `reason` are evaluated only on failure, so a check costs
/// nothing when it passes (validation may sit on per-step paths).
macro_rules! require {
    ($ok:expr, $field:expr, $reason:expr $(,)?) => {{
        let ok: bool = $ok;
        if !ok {
            return Err($crate::error::ConfigError::invalid($field, $reason).into());
        }
    }};
}
pub(crate) use require;

impl From<PartitionError> for SimError {
    fn from(e: PartitionError) -> Self {
        Self::Grid(e)
    }
}

/// `Ok` if `v` is a positive finite number, else an error naming `field`.
pub(crate) fn positive(field: &str, v: f64) -> Result<(), ConfigError> {
    require!(
        v > 0.0 && v.is_finite(),
        field,
        format!("must be a positive number, got {v}")
    );
    Ok(())
}

/// `Ok` if every value is finite in single precision as well (`|v| <= f32::MAX`, about
/// 3.4e38): the solver runs in `f32` by default, so an action, a bound or a core beyond it
/// would become infinite there. The error names `field` and the first value out of range.
pub(crate) fn single_precision(field: &str, values: &[f64]) -> Result<(), ConfigError> {
    if let Some(v) = values
        .iter()
        .find(|v| !(v.is_finite() && v.abs() <= f64::from(f32::MAX)))
    {
        return Err(ConfigError::invalid(
            field,
            format!("must be finite numbers within single precision (|x| <= 3.4e38), got {v}"),
        ));
    }
    Ok(())
}

/// `Ok` if `v` is a finite number `>= 0`, else an error naming `field`.
pub(crate) fn non_negative(field: &str, v: f64) -> Result<(), ConfigError> {
    require!(
        v >= 0.0 && v.is_finite(),
        field,
        format!("must be a non-negative number, got {v}")
    );
    Ok(())
}

/// `Ok` if `v` is a discount factor in `[0, 1)`, else an error naming `field`.
pub(crate) fn discount(field: &str, v: f64) -> Result<(), ConfigError> {
    require!(
        (0.0..1.0).contains(&v),
        field,
        format!("must be in [0, 1), got {v}")
    );
    Ok(())
}

/// Why a checkpoint cannot be read, written or continued.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// Reading failed.
    #[error("cannot read checkpoint {}: {error}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// Writing failed (the previous checkpoint, if any, is intact).
    #[error("cannot write checkpoint {}: {error}", path.display())]
    Write {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        error: std::io::Error,
    },
    /// The file is not a checkpoint.
    #[error("{} is not a fuzzyq checkpoint{}", path.display(), if *policy { " (it is a policy file)" } else { "" })]
    NotACheckpoint {
        /// The file.
        path: PathBuf,
        /// It is a policy file.
        policy: bool,
    },
    /// The file is damaged or of another format version.
    #[error("checkpoint {} {reason}", path.display())]
    Damaged {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// The checkpoint was written by a run of other settings.
    #[error(
        "checkpoint {} was written by a run with other settings: {difference}; run the same \
         command that wrote it",
        path.display()
    )]
    Settings {
        /// The file.
        path: PathBuf,
        /// The first difference.
        difference: String,
    },
}
