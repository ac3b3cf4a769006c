//! Typed errors of the kernels. Every fallible function returns one of these; none panics on
//! bad input or allocates to report it.

use core::fmt;

/// Why a list of cores is not a valid triangular partition of one state variable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum CoresError {
    /// Fewer than two cores.
    TooFew {
        /// How many cores were given.
        found: usize,
    },
    /// A core is NaN or infinite.
    NotFinite {
        /// Position of the offending core.
        index: usize,
    },
    /// `cores[index] <= cores[index - 1]`: cores must increase strictly.
    NotIncreasing {
        /// Position of the first core that does not exceed its predecessor.
        index: usize,
    },
}

impl fmt::Display for CoresError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::TooFew { found } => {
                write!(f, "a partition needs at least 2 cores, found {found}")
            }
            Self::NotFinite { index } => write!(f, "core {index} is not a finite number"),
            Self::NotIncreasing { index } => write!(
                f,
                "cores must increase strictly, but core {index} does not exceed core {}",
                index - 1
            ),
        }
    }
}

impl core::error::Error for CoresError {}

/// Why a product partition (a fuzzy grid over several state variables) cannot be built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum PartitionError {
    /// The cores of one dimension are invalid.
    Cores {
        /// The state variable (0-based).
        dim: usize,
        /// What is wrong with its cores.
        error: CoresError,
    },
    /// No dimensions were given.
    NoDimensions,
    /// More dimensions than [`MAX_DIMS`](crate::MAX_DIMS).
    TooManyDimensions {
        /// How many were given.
        found: usize,
    },
    /// The number of joint cores overflows `usize`. (Only the generic backup path and
    /// Q-iteration, whose tables index cores in 32 bits, stop at 2^32 cores:
    /// [`SolveError::TooLarge`](crate::solver::SolveError::TooLarge).)
    TooManyCores,
}

impl fmt::Display for PartitionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Cores { dim, error } => write!(f, "state variable {dim}: {error}"),
            Self::NoDimensions => f.write_str("a fuzzy grid needs at least one state variable"),
            Self::TooManyDimensions { found } => write!(
                f,
                "a fuzzy grid has at most {} state variables, found {found}",
                crate::limits::MAX_DIMS
            ),
            Self::TooManyCores => {
                f.write_str("the number of joint cores overflows this machine's indices (usize)")
            }
        }
    }
}

impl core::error::Error for PartitionError {}

/// Why an evaluation (memberships, Q-values, policies, backups) was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub enum EvalError {
    /// A slice has the wrong length.
    Length {
        /// What the slice holds.
        what: &'static str,
        /// The length the call needs.
        expected: usize,
        /// The length given.
        found: usize,
    },
    /// A value that must be finite is NaN or infinite.
    NotFinite {
        /// What the slice holds.
        what: &'static str,
        /// Position of the offending value.
        index: usize,
    },
    /// An index is out of range.
    OutOfRange {
        /// What the index counts.
        what: &'static str,
        /// The offending index.
        index: usize,
        /// The number of valid indices.
        len: usize,
    },
    /// A finite input that the evaluation's precision cannot hold (a state of `1e300` for a
    /// solution in `f32`, whose largest number is about `3.4e38`).
    BeyondPrecision {
        /// What the input is.
        what: &'static str,
        /// Its first such element.
        index: usize,
    },
    /// The model has more agents than [`MAX_AGENTS`](crate::MAX_AGENTS), or none.
    Agents {
        /// How many agents the model declares.
        found: usize,
    },
}

impl fmt::Display for EvalError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Length {
                what,
                expected,
                found,
            } => write!(f, "{what}: expected length {expected}, found {found}"),
            Self::NotFinite { what, index } => {
                write!(f, "{what}: element {index} is not a finite number")
            }
            Self::BeyondPrecision { what, index } => write!(
                f,
                "{what}: element {index} is beyond the solution's precision (single precision \
                 holds |x| <= 3.4e38)"
            ),
            Self::OutOfRange { what, index, len } => {
                write!(f, "{what}: index {index} is out of range 0..{len}")
            }
            Self::Agents { found } => write!(
                f,
                "a model needs between 1 and {} agents, found {found}",
                crate::limits::MAX_AGENTS
            ),
        }
    }
}

impl core::error::Error for EvalError {}

/// Checks a slice length, naming the slice in the error.
#[inline]
pub fn check_len(what: &'static str, expected: usize, found: usize) -> Result<(), EvalError> {
    if expected == found {
        Ok(())
    } else {
        Err(EvalError::Length {
            what,
            expected,
            found,
        })
    }
}

/// Checks that a buffer is at least `needed` long.
#[inline]
pub(crate) fn check_at_least(
    what: &'static str,
    needed: usize,
    found: usize,
) -> Result<(), EvalError> {
    if found >= needed {
        Ok(())
    } else {
        Err(EvalError::Length {
            what,
            expected: needed,
            found,
        })
    }
}
