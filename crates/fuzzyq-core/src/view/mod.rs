//! A trained policy read in place from bytes: [`PolicyView`] checks an exported policy
//! (`include_bytes!` of a file, or flash memory) and borrows its grid, action sets, per-core
//! greedy actions and optionally `V` without copying or allocating, so a `no_std` controller
//! without an allocator can act with it.
//!
//! # The format (version 1)
//! Little-endian throughout; every section starts at a multiple of 8 bytes from the start.
//!
//! | offset | field |
//! |---|---|
//! | 0 | tag `\x89FZQVIEW` (8 bytes) |
//! | 8 | format version, `u32` (1) |
//! | 12 | bytes per value: 4 (`f32`) or 8 (`f64`), `u32` |
//! | 16 | bytes per greedy action: 1, 2 or 4, `u32` |
//! | 20 | membership: 0 triangular, 1 crisp, `u32` |
//! | 24 | state variables `E`, `u32` |
//! | 28 | agents `N`, `u32` |
//! | 32 | cores (the product of the core counts), `u64` |
//! | 40 | whether `V` follows, `u32` (0 or 1) |
//! | 44 | decision tables: 0 none; 2 they follow `V`, and `V` is in their decision order (see [`decide`]); 1 (an earlier layout, `V` in grid order) is refused: export again, `u32` |
//! | 48 | payload bytes (everything after this 64-byte header up to the checksum), `u64` |
//! | 56 | 8 bytes of zeros |
//! | 64 | payload: `E` core counts (`u32`), then `N` pairs (actions, components) (`u32`); the cores of every variable; the actions of every agent (action-major); the greedy joint action of every core (row-major core order); `V` per core if present (row-major core order, or decision order with decision tables); the decision tables if present. Each section padded with zeros to a multiple of 8 bytes |
//! | 64 + payload | CRC-32 (ISO-HDLC, as zlib's) of every byte before it, `u32`, then 4 bytes of zeros |
//!
//! The view refuses, with a typed [`ViewError`], bytes that are not such a file, that are cut
//! short, damaged (checksum), of another precision or version, on a big-endian CPU (the values
//! are borrowed as they are stored; a generated Rust module works there), misaligned in memory (the
//! values are borrowed as `&[f32]`/`&[f64]`: place the bytes at an 8-byte boundary, for
//! example in a `#[repr(align(8))]` wrapper), or whose contents are invalid (unsorted cores,
//! greedy actions that name no joint action).
//!
//! # Decisions
//! - The interpolated policy (eq 22) needs the greedy actions only:
//!   [`PolicyView::interpolated_action`].
//! - The greedy policy (eq 7) needs `Q(x, .)`, so `V` and the model's transitions:
//!   - from the decision tables an export with `--greedy` carries (block-path models: the
//!     paper's point masses), without the model: [`PolicyView::q_values`] and
//!     [`PolicyView::greedy_action`] on a caller's scratch of
//!     [`PolicyView::decision_scratch_len`] words;
//!   - or from the model, where the controller has one (any model implementing
//!     [`crate::Model`]): [`PolicyView::q_values_with_model`].
//!
//!   Both give the bits of the solver's `Operator::q_values` on the laptop.

pub mod decide;

pub use decide::DecideError;
use decide::Decisions;

use core::fmt;

use crate::action::{ActionSet, JointActions};
use crate::backup::Backup;
use crate::error::{EvalError, PartitionError};
use crate::limits::{MAX_AGENTS, MAX_DIMS};
use crate::model::Model;
use crate::partition::{Membership, ProductPartition};
use crate::q::{GreedyTable, interpolated_action_in};
use crate::real::Real;

/// The tag every exported policy starts with.
pub const MAGIC: [u8; 8] = *b"\x89FZQVIEW";
/// The format version this build reads.
pub const VERSION: u32 = 1;
/// Bytes of the header.
pub const HEADER_LEN: usize = 64;

/// Why bytes are not a usable exported policy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ViewError {
    /// The bytes do not start with [`MAGIC`].
    NotAPolicy,
    /// Another format version.
    Version {
        /// The version found.
        found: u32,
    },
    /// Fewer bytes than the header announces.
    Truncated {
        /// Bytes needed.
        needed: usize,
        /// Bytes given.
        found: usize,
    },
    /// The checksum does not match: the bytes are damaged.
    Checksum {
        /// The stored CRC-32.
        stored: u32,
        /// The CRC-32 of the bytes.
        computed: u32,
    },
    /// The values are of another precision than the view's type.
    Precision {
        /// Bytes per value in the file.
        found: u32,
        /// Bytes per value of the view's type.
        expected: u32,
    },
    /// The bytes do not start at an 8-byte boundary, so the values cannot be borrowed.
    Misaligned,
    /// This CPU is big-endian: the file's little-endian values cannot be borrowed in place
    /// (a generated Rust module, `fuzzyq export --format rust`, works on any CPU).
    BigEndian,
    /// A header field or section is invalid.
    Header {
        /// Which.
        what: &'static str,
    },
    /// The cores are not a valid grid.
    Grid(PartitionError),
    /// The action sets or the greedy actions are invalid.
    Actions(EvalError),
}

impl fmt::Display for ViewError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::NotAPolicy => write!(f, "not an exported fuzzyq policy (no \\x89FZQVIEW tag)"),
            Self::Version { found } => write!(
                f,
                "exported policy of format version {found}; this build reads version {VERSION}"
            ),
            Self::Truncated { needed, found } => write!(
                f,
                "exported policy cut short: {found} bytes, {needed} needed"
            ),
            Self::Checksum { stored, computed } => write!(
                f,
                "exported policy damaged: checksum {computed:#010x}, stored {stored:#010x}"
            ),
            Self::Precision { found, expected } => write!(
                f,
                "exported policy holds {found}-byte values; this view reads {expected}-byte values"
            ),
            Self::Misaligned => write!(
                f,
                "exported policy not at an 8-byte boundary in memory (wrap it in a \
                 #[repr(align(8))] struct)"
            ),
            Self::BigEndian => write!(
                f,
                "exported policy: this CPU is big-endian and the file little-endian, so it \
                 cannot be read in place (export with --format rust instead)"
            ),
            Self::Header { what } => write!(f, "exported policy: invalid {what}"),
            Self::Grid(e) => write!(f, "exported policy: grid: {e}"),
            Self::Actions(e) => write!(f, "exported policy: {e}"),
        }
    }
}

#[cfg(feature = "std")]
impl std::error::Error for ViewError {}

/// The greedy actions of an exported policy, in the width they were stored in.
#[derive(Clone, Copy, Debug)]
pub enum Greedy<'a> {
    /// One byte per core (at most 256 joint actions).
    U8(&'a [u8]),
    /// Two bytes per core (at most 65,536 joint actions).
    U16(&'a [u16]),
    /// Four bytes per core.
    U32(&'a [u32]),
}

impl GreedyTable for Greedy<'_> {
    #[inline]
    fn len(&self) -> usize {
        match self {
            Self::U8(g) => g.len(),
            Self::U16(g) => g.len(),
            Self::U32(g) => g.len(),
        }
    }

    #[inline]
    fn action(&self, core: usize) -> u32 {
        match self {
            Self::U8(g) => u32::from(g[core]),
            Self::U16(g) => u32::from(g[core]),
            Self::U32(g) => g[core],
        }
    }

    /// The width chosen once, not per core.
    fn gather(&self, cores: &[usize], out: &mut [u32]) -> u32 {
        match self {
            Self::U8(g) => g.gather(cores, out),
            Self::U16(g) => g.gather(cores, out),
            Self::U32(g) => g.gather(cores, out),
        }
    }
}

/// Bytes at an 8-byte boundary, as [`PolicyView::parse`] needs them: `include_bytes!` gives
/// bytes aligned to 1 only, so a controller wraps them.
///
/// ```
/// use fuzzyq_core::view::{Aligned, PolicyView, ViewError};
///
/// // A controller writes `&Aligned(*include_bytes!("policy.bin"))`.
/// static POLICY: &Aligned<[u8]> = &Aligned([0; 16]);
/// assert_eq!(
///     PolicyView::<f32>::parse(&POLICY.0).unwrap_err(),
///     ViewError::NotAPolicy
/// );
/// ```
#[repr(C, align(8))]
#[derive(Debug)]
pub struct Aligned<B: ?Sized>(pub B);

/// A value type a view can borrow from bytes (`f32`, `f64`).
pub trait ViewReal: Real + bytemuck::Pod {
    /// `a * b + c` rounded once (the fused multiply-add of the solver's kernels).
    fn fma(a: Self, b: Self, c: Self) -> Self;
}
impl ViewReal for f32 {
    #[inline]
    fn fma(a: Self, b: Self, c: Self) -> Self {
        libm::fmaf(a, b, c)
    }
}
impl ViewReal for f64 {
    #[inline]
    fn fma(a: Self, b: Self, c: Self) -> Self {
        libm::fma(a, b, c)
    }
}

/// An exported policy, checked and borrowed in place: its grid, joint action set, greedy
/// actions and optionally `V`. No allocation; a `no_std` controller can hold one in a
/// `static`'s lifetime.
#[derive(Clone, Copy, Debug)]
pub struct PolicyView<'a, T> {
    grid: ProductPartition<'a, T>,
    joint: JointActions<'a, T>,
    greedy: Greedy<'a>,
    v: Option<&'a [T]>,
    /// Each state variable's stride in `v`: the grid's, or the decision tables' order.
    value_strides: [usize; MAX_DIMS],
    decisions: Option<Decisions<'a, T>>,
}

/// Reads little-endian fields at increasing offsets.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], ViewError> {
        let end = self.at.checked_add(n).ok_or(ViewError::Header {
            what: "section length",
        })?;
        let s = self.bytes.get(self.at..end).ok_or(ViewError::Truncated {
            needed: end,
            found: self.bytes.len(),
        })?;
        self.at = end;
        Ok(s)
    }

    fn u32(&mut self) -> Result<u32, ViewError> {
        let b = self.take(4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    fn u64(&mut self) -> Result<u64, ViewError> {
        let b = self.take(8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_le_bytes(a))
    }

    /// `n` items of `U`, then the padding to a multiple of 8.
    fn section<U: bytemuck::Pod>(&mut self, n: usize) -> Result<&'a [U], ViewError> {
        let len = n
            .checked_mul(core::mem::size_of::<U>())
            .ok_or(ViewError::Header {
                what: "section length",
            })?;
        let s = self.take(len)?;
        self.take(padding(len))?;
        bytemuck::try_cast_slice(s).map_err(|_| ViewError::Misaligned)
    }
}

/// Zeros after `len` bytes up to a multiple of 8.
#[must_use]
pub const fn padding(len: usize) -> usize {
    (8 - len % 8) % 8
}

/// The header of an exported policy, checked (see [`PolicyView::parse`]).
struct Header {
    membership: Membership,
    n_dims: usize,
    n_agents: usize,
    n_cores: usize,
    has_v: bool,
    has_tables: bool,
    /// Bytes of a greedy action: 1, 2 or 4.
    greedy_bytes: u32,
    /// Where the payload ends (the checksum follows).
    end: usize,
}

impl Header {
    /// Reads and checks the header of `bytes` for values of type `T`: the tag, the
    /// platform, the alignment, the checksum over the payload (first: a damaged file is
    /// reported as damaged, whatever else it says), the version and every field's range.
    fn read<T: ViewReal>(bytes: &[u8]) -> Result<Self, ViewError> {
        if !bytes.starts_with(&MAGIC) {
            return Err(if bytes.len() < MAGIC.len() && MAGIC.starts_with(bytes) {
                ViewError::Truncated {
                    needed: HEADER_LEN,
                    found: bytes.len(),
                }
            } else {
                ViewError::NotAPolicy
            });
        }
        if cfg!(target_endian = "big") {
            return Err(ViewError::BigEndian);
        }
        if bytes.as_ptr().align_offset(8) != 0 {
            return Err(ViewError::Misaligned);
        }
        let mut r = Reader { bytes, at: 8 };
        let version = r.u32()?;
        let value_bytes = r.u32()?;
        let greedy_bytes = r.u32()?;
        let membership = r.u32()?;
        let (n_dims, n_agents) = (r.u32()? as usize, r.u32()? as usize);
        let n_cores = usize::try_from(r.u64()?).map_err(|_| ViewError::Header { what: "cores" })?;
        let has_v = r.u32()?;
        let has_tables = r.u32()?;
        let payload = usize::try_from(r.u64()?).map_err(|_| ViewError::Header {
            what: "payload length",
        })?;
        r.take(8)?;
        // The checksum first: a damaged file is reported as damaged, whatever else it says.
        let end = HEADER_LEN.checked_add(payload).ok_or(ViewError::Header {
            what: "payload length",
        })?;
        // The checksum and its padding: a file cut anywhere is refused, longer bytes (flash
        // beyond the file) are not read.
        let stored = bytes.get(end..end + 8).ok_or(ViewError::Truncated {
            needed: end + 8,
            found: bytes.len(),
        })?;
        let stored = u32::from_le_bytes([stored[0], stored[1], stored[2], stored[3]]);
        let computed = crc32(&bytes[..end]);
        if stored != computed {
            return Err(ViewError::Checksum { stored, computed });
        }
        // (Later versions keep this header, so their checksum is found and checked first.)
        if version != VERSION {
            return Err(ViewError::Version { found: version });
        }
        let membership = match membership {
            0 => Membership::Triangular,
            1 => Membership::Crisp,
            _ => return Err(ViewError::Header { what: "membership" }),
        };
        let has_v = match has_v {
            0 => false,
            1 => true,
            _ => return Err(ViewError::Header { what: "V flag" }),
        };
        let has_tables = match (has_tables, has_v) {
            (0, _) => false,
            (2, true) => true,
            (1, true) => {
                return Err(ViewError::Header {
                    what: "decision tables flag (1: tables of an earlier layout; export the policy again)",
                });
            }
            _ => {
                return Err(ViewError::Header {
                    what: "decision tables flag",
                });
            }
        };
        let expected = core::mem::size_of::<T>() as u32;
        if value_bytes != expected {
            return Err(ViewError::Precision {
                found: value_bytes,
                expected,
            });
        }
        if n_dims == 0 || n_dims > MAX_DIMS {
            return Err(ViewError::Header {
                what: "number of state variables",
            });
        }
        if n_agents == 0 || n_agents > MAX_AGENTS {
            return Err(ViewError::Header {
                what: "number of agents",
            });
        }
        Ok(Self {
            membership,
            n_dims,
            n_agents,
            n_cores,
            has_v,
            has_tables,
            greedy_bytes,
            end,
        })
    }
}

impl<'a, T: ViewReal> PolicyView<'a, T> {
    /// Checks `bytes` (an exported policy in `T`'s precision, at an 8-byte boundary) and
    /// borrows its parts.
    pub fn parse(bytes: &'a [u8]) -> Result<Self, ViewError> {
        let h = Header::read::<T>(bytes)?;
        let (n_dims, n_agents, n_cores, end) = (h.n_dims, h.n_agents, h.n_cores, h.end);
        let body = &bytes[..end];
        let mut r = Reader {
            bytes: body,
            at: HEADER_LEN,
        };
        let counts: &[u32] = r.section(n_dims)?;
        let shapes: &[u32] = r.section(2 * n_agents)?;
        let total_cores: usize = counts.iter().map(|&c| c as usize).sum();
        let cores: &[T] = r.section(total_cores)?;
        let mut slices: [&[T]; MAX_DIMS] = [&[]; MAX_DIMS];
        let mut at = 0;
        for (s, &c) in slices.iter_mut().zip(counts) {
            *s = &cores[at..at + c as usize];
            at += c as usize;
        }
        let grid = ProductPartition::try_new(&slices[..n_dims])
            .map_err(ViewError::Grid)?
            .with_membership(h.membership);
        if grid.n_cores() != n_cores {
            return Err(ViewError::Header { what: "cores" });
        }
        let total_actions = shapes
            .chunks_exact(2)
            .try_fold(0usize, |acc, s| {
                (s[0] as usize)
                    .checked_mul(s[1] as usize)
                    .and_then(|n| acc.checked_add(n))
            })
            .ok_or(ViewError::Header {
                what: "action set sizes",
            })?;
        let actions: &[T] = r.section(total_actions)?;
        let mut sets = [ActionSet::default(); MAX_AGENTS];
        let mut at = 0;
        for (set, s) in sets.iter_mut().zip(shapes.chunks_exact(2)) {
            let len = s[0] as usize * s[1] as usize;
            *set = ActionSet::try_new(&actions[at..at + len], s[1] as usize)
                .map_err(ViewError::Actions)?;
            if set.n_actions() != s[0] as usize {
                return Err(ViewError::Header {
                    what: "action set sizes",
                });
            }
            at += len;
        }
        let joint = JointActions::try_new(&sets[..n_agents]).map_err(ViewError::Actions)?;
        let greedy = match h.greedy_bytes {
            1 => Greedy::U8(r.section(n_cores)?),
            2 => Greedy::U16(r.section(n_cores)?),
            4 => Greedy::U32(r.section(n_cores)?),
            _ => {
                return Err(ViewError::Header {
                    what: "greedy action width",
                });
            }
        };
        let v = if h.has_v {
            Some(r.section::<T>(n_cores)?)
        } else {
            None
        };
        let decisions = if h.has_tables {
            Some(Decisions::read(&mut r, &grid, joint.n_joint())?)
        } else {
            None
        };
        if r.at != end {
            return Err(ViewError::Header {
                what: "payload length",
            });
        }
        let mut view = Self::from_parts(grid, joint, greedy, v)?;
        if let Some(d) = decisions {
            view.value_strides = d.value_strides();
            view.decisions = Some(d);
        }
        Ok(view)
    }

    /// A view of parts already in memory, for example the `static` arrays of a module that
    /// `fuzzyq export --format rust` generated: checks that `greedy` (and `v`, if given)
    /// hold one entry per core of `grid` and that every greedy action names a joint action.
    pub fn from_parts(
        grid: ProductPartition<'a, T>,
        joint: JointActions<'a, T>,
        greedy: Greedy<'a>,
        v: Option<&'a [T]>,
    ) -> Result<Self, ViewError> {
        let n_cores = grid.n_cores();
        if greedy.len() != n_cores {
            return Err(ViewError::Actions(EvalError::Length {
                what: "greedy actions",
                expected: n_cores,
                found: greedy.len(),
            }));
        }
        if let Some(v) = v
            && v.len() != n_cores
        {
            return Err(ViewError::Actions(EvalError::Length {
                what: "V",
                expected: n_cores,
                found: v.len(),
            }));
        }
        let n_joint = joint.n_joint();
        if let Some(u) = (0..n_cores)
            .map(|d| greedy.action(d))
            .find(|&u| u as usize >= n_joint)
        {
            return Err(ViewError::Actions(EvalError::OutOfRange {
                what: "greedy action",
                index: u as usize,
                len: n_joint,
            }));
        }
        let mut value_strides = [0; MAX_DIMS];
        value_strides[..grid.n_dims()].copy_from_slice(grid.strides());
        Ok(Self {
            grid,
            joint,
            greedy,
            v,
            value_strides,
            decisions: None,
        })
    }

    /// The grid.
    #[must_use]
    pub fn grid(&self) -> &ProductPartition<'a, T> {
        &self.grid
    }

    /// The joint action set.
    #[must_use]
    pub fn joint(&self) -> &JointActions<'a, T> {
        &self.joint
    }

    /// The per-core greedy joint actions, in the width they were stored in.
    #[must_use]
    pub fn greedy(&self) -> Greedy<'a> {
        self.greedy
    }

    /// `V` per core, if it was exported: row-major over the grid's cores, or, in an export
    /// with decision tables, in their decision order; [`Self::value_strides`] says where
    /// each core is.
    #[must_use]
    pub fn values(&self) -> Option<&'a [T]> {
        self.v
    }

    /// Each state variable's stride in [`Self::values`]: core `(i_0, .., i_E-1)` is at
    /// `sum_d i_d strides[d]`. The grid's strides, except in an export with decision tables
    /// (their decision order: see [`decide`]).
    #[must_use]
    pub fn value_strides(&self) -> &[usize] {
        &self.value_strides[..self.grid.n_dims()]
    }

    /// The interpolated policy (eq 22) at state `x` into `out` (`joint().dim()` components):
    /// [`crate::q::interpolated_action`], the same bits as from the policy the file was
    /// exported from.
    pub fn interpolated_action(&self, x: &[T], out: &mut [T]) -> Result<(), EvalError> {
        interpolated_action_in(&self.grid, &self.joint, &self.greedy, x, out)
    }

    /// Whether the export carries decision tables (`fuzzyq export --greedy`), so that
    /// [`Self::q_values`] and [`Self::greedy_action`] work without the model.
    #[must_use]
    pub fn has_decision_tables(&self) -> bool {
        self.decisions.is_some()
    }

    /// The `u64` words of scratch [`Self::q_values`] and [`Self::greedy_action`] need
    /// (`None` without decision tables): a controller sizes a `static` buffer by it.
    #[must_use]
    pub fn decision_scratch_len(&self) -> Option<usize> {
        self.decisions.map(|d| d.scratch_words())
    }

    /// `out[u] = Q(x, u)` for every joint action (`joint().n_joint()` values) from the
    /// decision tables and `V`, on the caller's `scratch` (at least
    /// [`Self::decision_scratch_len`] words): the bits of the solver's `Operator::q_values`.
    /// No allocation.
    pub fn q_values(&self, x: &[T], scratch: &mut [u64], out: &mut [T]) -> Result<(), DecideError> {
        let (Some(d), Some(v)) = (&self.decisions, self.v) else {
            return Err(DecideError::NoTables);
        };
        Ok(d.q_values(&self.grid, v, x, scratch, out)?)
    }

    /// The greedy policy (eq 7) at `x` from the decision tables: writes `Q(x, .)` into `q`
    /// (`joint().n_joint()` values) and the action vector into `u` (`joint().dim()` values),
    /// and returns the joint action index (the lowest on ties, as the solver's).
    pub fn greedy_action(
        &self,
        x: &[T],
        scratch: &mut [u64],
        q: &mut [T],
        u: &mut [T],
    ) -> Result<usize, DecideError> {
        crate::error::check_len("joint action vector", self.joint.dim(), u.len())?;
        self.q_values(x, scratch, q)?;
        let best = crate::q::argmax(q).unwrap_or(0);
        self.joint.vector(best, u)?;
        Ok(best)
    }

    /// `out[u] = Q(x, u)` from `V` and a model the controller has (any [`Model`]: the
    /// generic backup, [`crate::backup::q_values_from_v`]); `scratch` and `row` as that
    /// function takes them. The bits of the solver's generic path.
    #[allow(clippy::too_many_arguments)] // a backup's inputs, spelled out.
    pub fn q_values_with_model<M: Model<T> + ?Sized>(
        &self,
        model: &M,
        backup: Backup<T>,
        x: &[T],
        scratch: &mut [T],
        row: &mut [T],
        out: &mut [T],
    ) -> Result<(), DecideError> {
        let v = self.v.ok_or(DecideError::NoValues)?;
        if self.decisions.is_some() {
            return Err(DecideError::DecisionOrder);
        }
        Ok(crate::backup::q_values_from_v(
            model,
            &self.grid,
            &self.joint,
            v,
            backup,
            x,
            scratch,
            row,
            out,
        )?)
    }

    /// `V` interpolated at `x` (`None` if `V` was not exported): the bits of the
    /// interpolation on the grid, in either order of `V`.
    pub fn value(&self, x: &[T]) -> Option<Result<T, EvalError>> {
        let strides = self.value_strides();
        self.v.map(|v| {
            self.grid
                .active_with_strides(x, strides)
                .map(|a| a.interpolate(v))
        })
    }
}

/// CRC-32 (ISO-HDLC: reflected, polynomial 0xEDB88320, as zlib's) of `bytes`.
#[must_use]
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut h = crc32fast::Hasher::new();
    h.update(bytes);
    h.finalize()
}
