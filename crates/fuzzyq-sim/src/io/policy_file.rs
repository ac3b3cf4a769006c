//! Policy files: one versioned, checksummed container for every learner, written
//! atomically, and one loader that reads a file once and dispatches on what it holds.
//!
//! # Layout (little-endian)
//! | bytes | content |
//! |---|---|
//! | 8 | magic tag `\x89FUZZYQ\n` (the high byte catches 7-bit and text-mode mangling) |
//! | 4 | format version, `u32` (4 for a policy of a learned model, 5 for a solution of a model defined in Python (`TabulatedArtifact`), else 2; versions 1 and 3 are still read: version 1 files hold fuzzy Q-iteration only, version 3 learned tables without their membership functions, which were then always triangular) |
//! | 8 | payload length in bytes, `u64` |
//! | 4 | CRC-32 of the payload, `u32` |
//! | n | payload in postcard encoding: which learner, then its content |
//!
//! The payload of a fuzzy Q-iteration policy ([`PolicyArtifact`]) holds the training
//! configuration (as its TOML text), `V` per core, the per-core greedy joint actions and the
//! training summary; a policy of a learned model (`--learner learned-model`) also holds the
//! learned transition tables ([`BlockTables`]), since its model cannot be rebuilt from the
//! configuration. A policy learned from samples ([`PointMassPolicyFile`],
//! [`KheperaPolicyFile`]) travels as the TOML text of its task, learning settings and
//! parameters (floats round-trip exactly). Files written before version 2 kept learned
//! policies as plain TOML; [`PolicyFile::from_bytes`] still reads them.
//!
//! A file is written to a temporary file in the destination's directory, flushed and renamed
//! over the destination, so a crash or a full disk never leaves a half-written policy. It is
//! encoded as it is written, and a payload of a GiB or more is decoded as it is read, checked
//! all the same (three point masses on the paper's cores make a 48 GB file, held once).
//! Reading checks the tag, version, length, checksum and the content's consistency, and names
//! what is wrong.

use std::path::Path;

use fuzzyq_core::solver::Precision;
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, PolicyFileError, SimError, require};
use crate::io::config::{TomlDoc, TrainConfig};
use crate::io::container::{Decode, Decoder, Encoder, Source};
use crate::learn::additive::AdditiveQ;
use crate::learn::fql::{FqlConfig, FqlOutcome};
use crate::learn::tasks::khepera as khepera_task;
use crate::learn::tasks::pointmass as pointmass_task;
use crate::learn::vqql::VqqlConfig;
use crate::model::khepera::KheperaConfig;
use crate::model::learned::{BlockTables, LearnedModel};
use crate::model::pointmass::{PointMass, PointMassConfig, Starts};

/// The magic tag every policy file starts with.
pub const MAGIC: [u8; 8] = *b"\x89FUZZYQ\n";
/// The newest format version this build writes (it reads versions 1 to 4): version 3 added
/// the payload of a learned model's policy and version 4 the membership functions of its
/// tables; only such policies are written as version 4, so that every other file stays
/// readable by builds that read version 2.
pub const FORMAT_VERSION: u32 = 5;
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

    /// The values as their derived serialisation encodes them, in bulk.
    fn encode<W: std::io::Write>(&self, e: &mut Encoder<W>) -> std::io::Result<()> {
        match self {
            Self::F32(v) => {
                e.variant(0)?;
                e.floats(v)
            }
            Self::F64(v) => {
                e.variant(1)?;
                e.floats(v)
            }
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
    /// Wall-clock seconds of the solve (0 in a file: files keep no timings).
    pub seconds: f64,
    /// The a-priori sweep bound (eq 37).
    pub sweep_bound: usize,
    /// `max |rho|` over cores and joint actions.
    pub reward_bound: f64,
    /// Backup path used: `"block"` or `"generic"`.
    pub backup: String,
    /// Kernel instance: `"avx512"`, `"avx2"`, `"portable"`, `"scalar"` or `"generic"`.
    pub kernel: String,
    /// Multiply-adds of one sweep on the block path.
    pub multiply_adds_per_sweep: Option<f64>,
    /// Seconds spent in sweeps (the solve minus its set-up and the final passes; 0 in a file).
    pub sweep_seconds: f64,
    /// The fuzzyq version that trained it.
    pub fuzzyq_version: String,
    /// The sweeps (from 1) that were policy-evaluation sweeps of modified policy iteration,
    /// and the seconds they took; known after training, not stored in the file.
    #[serde(skip)]
    pub evaluation: Vec<usize>,
    /// Seconds of the evaluation sweeps (not stored in the file).
    #[serde(skip)]
    pub evaluation_seconds: f64,
    /// The run's coarse start, if it had one (not stored in the file; boxed: the summary
    /// stays small).
    #[serde(skip)]
    pub coarse: Option<Box<fuzzyq_core::solver::CoarseStart>>,
    /// Seconds before the first sweep, the coarse start aside: the operator and the
    /// backend's buffers ([`Solution::setup_seconds`](fuzzyq_core::solver::Solution); not
    /// stored in the file).
    #[serde(skip)]
    pub setup_seconds: Option<f64>,
    /// Seconds bringing `V` and the greedy actions into grid order at the end
    /// ([`Solution::result_seconds`](fuzzyq_core::solver::Solution); not stored in the file).
    #[serde(skip)]
    pub result_seconds: Option<f64>,
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
            evaluation: s
                .sweeps
                .iter()
                .filter(|r| r.evaluation)
                .map(|r| r.sweep)
                .collect(),
            evaluation_seconds: s.evaluation_seconds,
            coarse: s.coarse.map(Box::new),
            setup_seconds: s.setup_seconds,
            result_seconds: s.result_seconds,
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
    /// The transition tables of the learned model it was solved on (`--learner
    /// learned-model`); `None` for the environment's own model.
    pub learned: Option<Box<BlockTables>>,
}

/// A fuzzy Q-iteration policy as version 1 and the [`Content::Fqi`] of version 2 encode it:
/// the configuration travels as its TOML text (postcard cannot encode the config's internally
/// tagged enums, and TOML keeps it readable and stable across versions).
#[derive(Deserialize)]
#[cfg_attr(test, derive(PartialEq))]
struct FqiPayload {
    config_toml: String,
    values: Values,
    greedy: Vec<u32>,
    summary: TrainSummary,
}

/// [`FqiPayload`] borrowed for writing (the same fields in the same order: postcard encodes a
/// reference, a slice and a `Vec` alike), so saving copies no table.
#[derive(Serialize)]
struct FqiPayloadRef<'a> {
    config_toml: String,
    values: &'a Values,
    greedy: &'a [u32],
    summary: &'a TrainSummary,
}

impl FqiPayloadRef<'_> {
    /// The payload as its derived serialisation encodes it, `V` and the greedy actions in
    /// bulk.
    fn encode<W: std::io::Write>(&self, e: &mut Encoder<W>) -> std::io::Result<()> {
        e.value(&self.config_toml)?;
        self.values.encode(e)?;
        e.u32s(self.greedy)?;
        e.value(self.summary)
    }
}

/// What a version 2 or 3 payload holds: `F` is [`FqiPayload`] and `L` [`BlockTables`] when
/// reading, [`FqiPayloadRef`] and a reference when writing. Variants are only ever added at
/// the end (postcard encodes the variant's index).
#[derive(Serialize, Deserialize)]
#[cfg_attr(test, derive(PartialEq))]
enum Content<F, L> {
    /// Fuzzy Q-iteration.
    Fqi(F),
    /// A point-mass policy learned from samples, as TOML text.
    PointMass(String),
    /// A Khepera policy learned from samples, as TOML text.
    Khepera(String),
    /// Fuzzy Q-iteration on a learned model, with its tables (versions 3 and 4).
    LearnedFqi(F, L),
    /// Fuzzy Q-iteration on a model defined outside fuzzyq (version 5).
    Tabulated(Box<TabulatedArtifact>),
}

impl Content<FqiPayloadRef<'_>, &BlockTables> {
    /// The payload as its derived serialisation encodes it (the variant's index, then its
    /// fields), the per-core arrays in bulk: `postcard::to_stdvec(self)`'s bytes, as
    /// `every_payload_is_written_as_serde_encodes_it` checks.
    fn encode<W: std::io::Write>(&self, e: &mut Encoder<W>) -> std::io::Result<()> {
        match self {
            Self::Fqi(p) => {
                e.variant(0)?;
                p.encode(e)
            }
            Self::LearnedFqi(p, tables) => {
                e.variant(3)?;
                p.encode(e)?;
                e.value(tables)
            }
            Self::Tabulated(t) => {
                e.variant(4)?;
                let t = &**t;
                e.value(&(&t.cores, &t.membership, &t.actions, &t.blocks))?;
                t.values.encode(e)?;
                e.u32s(&t.greedy)?;
                e.value(&(t.gamma, t.xi, t.absorbing_goal, &t.summary))
            }
            Self::PointMass(_) | Self::Khepera(_) => e.value(self),
        }
    }
}

impl<L: serde::de::DeserializeOwned> Decode for Content<FqiPayload, L> {
    /// The payload as its derived deserialisation decodes it, the per-core arrays in bulk
    /// (the mirror of [`Content::encode`]; `every_payload_is_read_as_serde_decodes_it`).
    fn decode<S: Source>(d: &mut Decoder<S>) -> postcard::Result<Self> {
        Ok(match d.variant()? {
            0 => Self::Fqi(FqiPayload::decode(d)?),
            1 => Self::PointMass(d.value()?),
            2 => Self::Khepera(d.value()?),
            3 => Self::LearnedFqi(FqiPayload::decode(d)?, d.value()?),
            4 => {
                let (cores, membership, actions, blocks) = d.value()?;
                let (values, greedy) = (Values::decode(d)?, d.u32s()?);
                let (gamma, xi, absorbing_goal, summary) = d.value()?;
                Self::Tabulated(Box::new(TabulatedArtifact {
                    cores,
                    membership,
                    actions,
                    blocks,
                    values,
                    greedy,
                    gamma,
                    xi,
                    absorbing_goal,
                    summary,
                }))
            }
            _ => return Err(postcard::Error::DeserializeBadEnum),
        })
    }
}

impl Decode for FqiPayload {
    fn decode<S: Source>(d: &mut Decoder<S>) -> postcard::Result<Self> {
        Ok(Self {
            config_toml: d.value()?,
            values: Values::decode(d)?,
            greedy: d.u32s()?,
            summary: d.value()?,
        })
    }
}

impl Decode for Values {
    fn decode<S: Source>(d: &mut Decoder<S>) -> postcard::Result<Self> {
        match d.variant()? {
            0 => d.floats().map(Self::F32),
            1 => d.floats().map(Self::F64),
            _ => Err(postcard::Error::DeserializeBadEnum),
        }
    }
}

/// A container's payload to decode: in memory, its length and checksum checked, or the rest
/// of a file, checked as it is read.
enum Payload<'a> {
    Bytes(&'a [u8]),
    Stream {
        file: std::fs::File,
        len: u64,
        crc: u32,
    },
}

impl Payload<'_> {
    /// The payload's content as a `T`; `path` names the file in errors.
    fn decode<T: Decode>(self, path: &Path) -> Result<T, PolicyFileError> {
        use super::container::Streamed;
        let (file, len, crc) = match self {
            Self::Bytes(b) => {
                return super::container::decode_payload(b).map_err(|e| malformed(path, e));
            }
            Self::Stream { file, len, crc } => (file, len, crc),
        };
        super::container::decode_streamed_as(file, len, crc).map_err(|e| match e {
            Streamed::Io(error) => PolicyFileError::Read {
                path: path.to_path_buf(),
                error,
            },
            Streamed::Damage(d) => damaged(path, len, d),
            Streamed::Content(reason) => malformed(path, reason),
        })
    }
}

/// A fuzzy Q-iteration solution of a model defined outside fuzzyq (a Python
/// `fuzzyq.CallableModel`): everything acting needs but the model's function, which a file
/// cannot hold. Python's `fuzzyq.load(path, model=...)` reads it back with the model; the
/// command line refuses it by name.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TabulatedArtifact {
    /// The grid's cores per state variable.
    pub cores: Vec<Vec<f64>>,
    /// The grid's membership functions.
    pub membership: fuzzyq_core::Membership,
    /// Each agent's actions: values (action-major) and components per action.
    pub actions: Vec<(Vec<f64>, usize)>,
    /// The model's declared independent dynamics blocks: state variables and action
    /// components (empty: none).
    pub blocks: Vec<(Vec<usize>, Vec<usize>)>,
    /// `V` per core, in the solver's precision.
    pub values: Values,
    /// The greedy joint action of every core.
    pub greedy: Vec<u32>,
    /// Discount factor.
    pub gamma: f64,
    /// Stopping threshold.
    pub xi: f64,
    /// Whether goal states were absorbing.
    pub absorbing_goal: bool,
    /// How the solve went.
    pub summary: TrainSummary,
}

impl TabulatedArtifact {
    /// Checks the artifact's internal consistency.
    pub fn check(&self) -> Result<(), String> {
        let grid = fuzzyq_core::solver::Grid::new(self.cores.clone()).map_err(|e| e.to_string())?;
        let n = grid.n_cores();
        if self.values.len() != n || self.greedy.len() != n {
            return Err(format!(
                "{} values and {} greedy actions for a grid of {n} cores",
                self.values.len(),
                self.greedy.len()
            ));
        }
        if !self.values.all_finite() {
            return Err("a value is not a finite number".into());
        }
        let mut m = 1usize;
        for (values, dim) in &self.actions {
            let set = fuzzyq_core::ActionSet::try_new(values, *dim).map_err(|e| e.to_string())?;
            m = m.saturating_mul(set.n_actions());
        }
        if self.actions.is_empty() {
            return Err("no agents".into());
        }
        if let Some(u) = self.greedy.iter().find(|&&u| u as usize >= m) {
            return Err(format!("greedy action {u} is out of range 0..{m}"));
        }
        if !(0.0..1.0).contains(&self.gamma) {
            return Err(format!("gamma {} is not in [0, 1)", self.gamma));
        }
        Ok(())
    }
}

/// [`BlockTables`] as version 3 encoded them: before crisp grids could be learned, so their
/// memberships were always triangular.
#[derive(Deserialize)]
struct BlockTablesV3 {
    cores: Vec<Vec<f64>>,
    blocks: Vec<crate::model::learned::BlockTable>,
}

impl From<BlockTablesV3> for BlockTables {
    fn from(v3: BlockTablesV3) -> Self {
        Self {
            cores: v3.cores,
            blocks: v3.blocks,
            membership: fuzzyq_core::Membership::Triangular,
        }
    }
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
        if let Some(tables) = &self.learned {
            let task = self.config.build_model().map_err(|e| e.to_string())?;
            if tables.cores != self.config.grid_cores()
                || tables.membership != self.config.grid.membership
            {
                return Err("the learned tables are not on the configured grid".into());
            }
            LearnedModel::new(task, (**tables).clone()).map_err(|e| e.to_string())?;
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
        self.config.n_joint_actions()
    }
}

/// A point-mass policy learned from samples (fuzzy Q-learning or VQQL) with what produced it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PointMassPolicyFile {
    /// The task.
    pub config: PointMassConfig,
    /// The episodes' starts.
    pub starts: Starts,
    /// The learning settings.
    pub fql: FqlConfig,
    /// The quantiser settings of a VQQL policy (its `q` has codebook features); `None` for
    /// fuzzy Q-learning.
    #[serde(default)]
    pub vqql: Option<VqqlConfig>,
    /// The learned Q-function.
    pub q: AdditiveQ,
    /// The first episode that passed the convergence test, if any.
    #[serde(default)]
    pub converged_at: Option<usize>,
    /// Learning episodes run.
    pub episodes: usize,
}

impl PointMassPolicyFile {
    /// The file of a fuzzy Q-learning run (`vqql = None`) or a
    /// [`train_vqql`](crate::learn::vqql::train_vqql) run (`vqql = Some(..)`).
    #[must_use]
    pub fn from_outcome(
        config: &PointMassConfig,
        starts: &Starts,
        fql: &FqlConfig,
        vqql: Option<&VqqlConfig>,
        outcome: &FqlOutcome,
    ) -> Self {
        Self {
            config: config.clone(),
            starts: starts.clone(),
            fql: fql.clone(),
            vqql: vqql.cloned(),
            q: outcome.q.clone(),
            converged_at: outcome.converged_at,
            episodes: outcome.curve.len(),
        }
    }

    /// Checks the file's parts against each other: valid configurations and starts, a
    /// Q-function that fits the model, codebook features exactly when `vqql` is set (with
    /// `vqql.cells` cells per agent).
    pub fn validate(&self) -> Result<PointMass, SimError> {
        let model = PointMass::new(self.config.clone())?;
        self.starts.validate(&model)?;
        self.fql.validate()?;
        pointmass_task::check_q(&model, &self.q)?;
        let features = self.q.features();
        match &self.vqql {
            Some(v) => {
                v.validate()?;
                require!(
                    features.is_codebook(),
                    "q",
                    "a VQQL policy (vqql set) needs codebook features",
                );
                if let Some(i) =
                    (0..features.n_agents()).find(|&i| features.n_cores(i) != Some(v.cells))
                {
                    return Err(ConfigError::invalid(
                        "q",
                        format!(
                            "agent {i}'s codebook has {:?} cells, vqql.cells = {}",
                            features.n_cores(i),
                            v.cells
                        ),
                    )
                    .into());
                }
            }
            None => {
                require!(
                    !features.is_codebook(),
                    "q",
                    "codebook features need the quantiser settings (vqql)",
                );
            }
        }
        Ok(model)
    }
}

/// A Khepera policy learned by fuzzy Q-learning with what produced it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KheperaPolicyFile {
    /// The task.
    pub config: KheperaConfig,
    /// The learning settings.
    pub fql: FqlConfig,
    /// The learned Q-function.
    pub q: AdditiveQ,
    /// The first episode that passed the convergence test, if any.
    #[serde(default)]
    pub converged_at: Option<usize>,
    /// Learning episodes run.
    pub episodes: usize,
}

impl KheperaPolicyFile {
    /// The file of a fuzzy Q-learning run.
    #[must_use]
    pub fn from_outcome(config: &KheperaConfig, fql: &FqlConfig, outcome: &FqlOutcome) -> Self {
        Self {
            config: config.clone(),
            fql: fql.clone(),
            q: outcome.q.clone(),
            converged_at: outcome.converged_at,
            episodes: outcome.curve.len(),
        }
    }

    /// Checks the file's parts against each other: valid settings and a Q-function learned
    /// on the feature space and actions of the configuration.
    pub fn validate(&self) -> Result<(), SimError> {
        self.fql.validate()?;
        khepera_task::check_q(&self.q, &self.config)
    }
}

/// The content of a policy file of any learner.
// One value per file read or written: the size of its largest variant costs nothing that a box
// would save.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Debug, PartialEq)]
pub enum PolicyFile {
    /// Fuzzy Q-iteration (`fuzzyq train`, the default learner).
    Fqi(PolicyArtifact),
    /// Fuzzy Q-learning or VQQL on the point masses.
    PointMass(PointMassPolicyFile),
    /// Fuzzy Q-learning on the Khepera robots.
    Khepera(KheperaPolicyFile),
    /// Fuzzy Q-iteration on a model defined in Python (`Solution.save` of a
    /// `fuzzyq.CallableModel`'s solution).
    Tabulated(Box<TabulatedArtifact>),
}

impl PolicyFile {
    /// Reads and checks a policy file of any kind, reading it once (a pipe or a FIFO works):
    /// see [`from_bytes`](Self::from_bytes).
    ///
    /// The container's header says how long it is, and no more than that is read; a file
    /// without the container's tag is read as TOML text of at most
    /// [`MAX_TEXT_BYTES`](crate::fs::MAX_TEXT_BYTES) (so `/dev/zero` is refused, not read forever).
    pub fn load(path: &Path) -> Result<Self, PolicyFileError> {
        Self::load_streaming_from(path, super::container::STREAM_FROM)
    }

    /// [`Self::load`], decoding a payload of at least `stream_from` bytes as it is read.
    fn load_streaming_from(path: &Path, stream_from: u64) -> Result<Self, PolicyFileError> {
        use super::container::Read as Found;
        use std::io::Read;
        let read_error = |error| PolicyFileError::Read {
            path: path.to_path_buf(),
            error,
        };
        // A container is read no further than its header's length (and one byte to see
        // whether more follow), nothing allocated ahead: a length of 2^64 in a short file is
        // found truncated, not reserved.
        let bytes =
            match super::container::read(path, &MAGIC, Some(stream_from)).map_err(read_error)? {
                Found::Container(bytes) => bytes,
                Found::Large(header, file) => {
                    let (version, len, crc) = Self::header(&header, path)?;
                    return Self::from_payload(version, Payload::Stream { file, len, crc }, path);
                }
                Found::Other(head, rest) => {
                    crate::fs::read_capped(head.as_slice().chain(rest), crate::fs::MAX_TEXT_BYTES)
                        .map_err(read_error)?
                }
            };
        Self::from_bytes(&bytes, path)
    }

    /// Decodes and checks bytes read from `path` (the path only names the file in errors): a
    /// container (the magic tag first, then version, length, checksum and content), or a
    /// policy learned from samples in the plain TOML of files written before version 2.
    pub fn from_bytes(bytes: &[u8], path: &Path) -> Result<Self, PolicyFileError> {
        let n = MAGIC.len().min(bytes.len());
        if !bytes.is_empty() && bytes[..n] == MAGIC[..n] {
            return Self::from_container(bytes, path);
        }
        Self::from_legacy_toml(bytes, path)
    }

    /// The version, payload length and checksum of a container's header (`bytes` from its
    /// start), checked.
    fn header(bytes: &[u8], path: &Path) -> Result<(u32, u64, u32), PolicyFileError> {
        if bytes.len() < HEADER_LEN {
            return Err(PolicyFileError::Truncated {
                path: path.to_path_buf(),
                found: bytes.len() as u64,
                expected: HEADER_LEN as u64,
            });
        }
        let version = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
        if !(1..=FORMAT_VERSION).contains(&version) {
            return Err(PolicyFileError::Version {
                path: path.to_path_buf(),
                found: version,
                supported: FORMAT_VERSION,
            });
        }
        let len = u64::from_le_bytes(bytes[12..20].try_into().expect("8 bytes"));
        let crc = u32::from_le_bytes(bytes[20..24].try_into().expect("4 bytes"));
        if len.checked_add(HEADER_LEN as u64).is_none() {
            return Err(malformed(
                path,
                format!("its header claims an impossible payload length ({len} bytes)"),
            ));
        }
        Ok((version, len, crc))
    }

    fn from_container(bytes: &[u8], path: &Path) -> Result<Self, PolicyFileError> {
        let (version, len, _) = Self::header(bytes, path)?;
        let (_, payload) = super::container::split(bytes).map_err(|d| damaged(path, len, d))?;
        Self::from_payload(version, Payload::Bytes(payload), path)
    }

    /// The file whose container of format `version` holds `payload`, decoded and checked.
    fn from_payload(
        version: u32,
        payload: Payload<'_>,
        path: &Path,
    ) -> Result<Self, PolicyFileError> {
        let content: Content<FqiPayload, BlockTables> = match version {
            1 => payload.decode(path).map(Content::Fqi),
            3 => payload
                .decode(path)
                .map(|p: Content<_, BlockTablesV3>| match p {
                    Content::LearnedFqi(f, tables) => Content::LearnedFqi(f, tables.into()),
                    Content::Fqi(f) => Content::Fqi(f),
                    Content::PointMass(text) => Content::PointMass(text),
                    Content::Khepera(text) => Content::Khepera(text),
                    Content::Tabulated(t) => Content::Tabulated(t),
                }),
            _ => payload.decode(path),
        }?;
        let fqi = |p: FqiPayload, learned: Option<Box<BlockTables>>| {
            let config = TrainConfig::from_toml(&p.config_toml)
                .map_err(|e| malformed(path, format!("its configuration: {e}")))?;
            Ok::<_, PolicyFileError>(Self::Fqi(PolicyArtifact {
                config,
                values: p.values,
                greedy: p.greedy,
                summary: p.summary,
                learned,
            }))
        };
        let file = match content {
            Content::Fqi(p) => fqi(p, None)?,
            Content::LearnedFqi(p, tables) => fqi(p, Some(Box::new(tables)))?,
            Content::PointMass(text) => Self::PointMass(from_toml(&text, path)?),
            Content::Khepera(text) => Self::Khepera(from_toml(&text, path)?),
            Content::Tabulated(t) => Self::Tabulated(t),
        };
        file.check().map_err(|reason| malformed(path, reason))?;
        Ok(file)
    }

    /// A learned policy in the plain TOML files written before version 2. A text whose
    /// top-level keys are a policy's is a policy: if it does not read, it is a damaged one
    /// ([`PolicyFileError::Malformed`], naming the line and the field), not something else
    /// ([`PolicyFileError::NotAPolicy`]).
    fn from_legacy_toml(bytes: &[u8], path: &Path) -> Result<Self, PolicyFileError> {
        let not_a_policy = || PolicyFileError::NotAPolicy {
            path: path.to_path_buf(),
        };
        let (text, bad_utf8) = match std::str::from_utf8(bytes) {
            Ok(text) => (text, None),
            Err(e) => {
                let valid = &bytes[..e.valid_up_to()];
                (
                    std::str::from_utf8(valid).expect("valid up to here"),
                    Some(e.valid_up_to()),
                )
            }
        };
        if !looks_like_a_policy(text) {
            return Err(not_a_policy());
        }
        if let Some(at) = bad_utf8 {
            return Err(malformed(
                path,
                format!(
                    "not UTF-8 text at byte {at} (line {})",
                    crate::io::config::line_at(text, at)
                ),
            ));
        }
        let robots = TomlDoc::parse(text).is_ok_and(|doc| {
            doc.table("config")
                .is_some_and(|c| c.contains_key("radius"))
        });
        let file = if robots {
            Self::Khepera(from_toml(text, path)?)
        } else {
            Self::PointMass(from_toml(text, path)?)
        };
        file.check().map_err(|reason| malformed(path, reason))?;
        Ok(file)
    }

    /// Checks the content's consistency.
    pub fn check(&self) -> Result<(), String> {
        match self {
            Self::Fqi(a) => a.check(),
            Self::PointMass(f) => f.validate().map(|_| ()).map_err(|e| e.to_string()),
            Self::Khepera(f) => f.validate().map_err(|e| e.to_string()),
            Self::Tabulated(t) => t.check(),
        }
    }

    /// Encodes the file with its header.
    pub fn to_bytes(&self) -> Result<Vec<u8>, SimError> {
        let out = std::io::Cursor::new(Vec::with_capacity(self.size_hint()));
        self.with_payload(|version, payload| {
            super::container::write_encoded(out, &MAGIC, version, |e| payload.encode(e))
                .expect("a policy always serialises, and a vector takes every byte")
                .into_inner()
        })
    }

    /// About how many bytes the file takes: exact for single-precision values and fewer than
    /// 128 joint actions (the greedy actions then take a byte each).
    fn size_hint(&self) -> usize {
        let (values, greedy) = match self {
            Self::Fqi(a) => (&a.values, a.greedy.len()),
            Self::Tabulated(t) => (&t.values, t.greedy.len()),
            Self::PointMass(_) | Self::Khepera(_) => return 1 << 16,
        };
        let each = match values {
            Values::F32(_) => 4,
            Values::F64(_) => 8,
        };
        HEADER_LEN + (1 << 16) + each * values.len() + greedy
    }

    /// Writes the file ([`Self::to_bytes`]'s bytes) to `out` as it is encoded, so that no copy
    /// of a large policy is held: the caller makes it atomic (a temporary file, then a rename).
    pub fn write_to<W: std::io::Write + std::io::Seek>(&self, out: W) -> std::io::Result<W> {
        self.with_payload(|version, payload| {
            super::container::write_encoded(out, &MAGIC, version, |e| payload.encode(e))
        })
        .map_err(|e| std::io::Error::other(e.to_string()))?
    }

    /// `f(version, payload)` of the file: what it is written as.
    fn with_payload<R>(
        &self,
        f: impl FnOnce(u32, &Content<FqiPayloadRef<'_>, &BlockTables>) -> R,
    ) -> Result<R, SimError> {
        let mut version = 2;
        let summary;
        let payload = match self {
            Self::Fqi(a) => {
                // Timings differ between identical runs: the file keeps none, so the same
                // configuration gives the same bytes (the `--json` summary has them).
                summary = TrainSummary {
                    seconds: 0.0,
                    sweep_seconds: 0.0,
                    ..a.summary.clone()
                };
                let p = FqiPayloadRef {
                    config_toml: a.config.to_toml(),
                    values: &a.values,
                    greedy: &a.greedy,
                    summary: &summary,
                };
                match &a.learned {
                    None => Content::Fqi(p),
                    Some(tables) => {
                        version = 4;
                        Content::LearnedFqi(p, &**tables)
                    }
                }
            }
            Self::PointMass(f) => Content::PointMass(to_toml(f)?),
            Self::Khepera(f) => Content::Khepera(to_toml(f)?),
            Self::Tabulated(t) => {
                version = 5;
                Content::Tabulated(Box::new(TabulatedArtifact {
                    summary: TrainSummary {
                        seconds: 0.0,
                        sweep_seconds: 0.0,
                        ..t.summary.clone()
                    },
                    ..(**t).clone()
                }))
            }
        };
        Ok(f(version, &payload))
    }

    /// Writes the policy file atomically (a temporary file in the same directory, then a
    /// rename), encoding it as it goes ([`Self::write_to`]).
    pub fn save(&self, path: &Path) -> Result<(), SimError> {
        super::write_atomically_with(path, |file| self.write_to(file).map(|_| ())).map_err(
            |error| {
                PolicyFileError::Write {
                    path: path.to_path_buf(),
                    error,
                }
                .into()
            },
        )
    }
}

/// The error of a container whose header announces a `len`-byte payload and that has
/// `damage`.
fn damaged(path: &Path, len: u64, damage: super::container::Damage) -> PolicyFileError {
    use super::container::Damage;
    let path = path.to_path_buf();
    match damage {
        Damage::Truncated { found, expected } => PolicyFileError::Truncated {
            path,
            found,
            expected,
        },
        Damage::Trailing(_) => malformed(
            &path,
            format!("data after the end its header gives ({len}-byte payload)"),
        ),
        Damage::Checksum => PolicyFileError::Checksum { path },
    }
}

fn malformed(path: &Path, reason: String) -> PolicyFileError {
    PolicyFileError::Malformed {
        path: path.to_path_buf(),
        reason,
    }
}

/// The top-level keys of a policy learned from samples ([`PointMassPolicyFile`],
/// [`KheperaPolicyFile`]).
const POLICY_KEYS: [&str; 7] = [
    "config",
    "starts",
    "fql",
    "vqql",
    "q",
    "converged_at",
    "episodes",
];

/// Whether `text` is (what is left of) the TOML of a policy learned from samples: its
/// top-level keys, as far as it reads, are a policy's and include the learning settings or
/// the Q-function, or the task with its episodes or starts.
fn looks_like_a_policy(text: &str) -> bool {
    let (root, _) = toml::de::DeTable::parse_recoverable(text);
    let keys: Vec<&str> = root
        .get_ref()
        .keys()
        .map(|k| k.get_ref().as_ref())
        .collect();
    let has = |k: &str| keys.contains(&k);
    !keys.is_empty()
        && keys.iter().all(|k| POLICY_KEYS.contains(k))
        && (has("fql") || has("q") || (has("config") && (has("episodes") || has("starts"))))
}

/// Reads the TOML of a policy learned from samples: a damaged one is named by its line and
/// field (`q.phi[0]: value is NaN (line 40)`, `... at the end of the text (truncated?)`).
fn from_toml<T: serde::de::DeserializeOwned + Serialize>(
    text: &str,
    path: &Path,
) -> Result<T, PolicyFileError> {
    let damaged = |e: crate::io::config::TomlError| malformed(path, e.to_string());
    let doc = TomlDoc::parse(text).map_err(damaged)?;
    if let Some(e) = doc.find_nan() {
        return Err(damaged(e));
    }
    doc.deserialize().map_err(damaged)
}

fn to_toml<T: Serialize>(value: &T) -> Result<String, SimError> {
    toml::to_string(value)
        .map_err(|e| crate::error::ConfigError::Parse(format!("policy file: {e}")).into())
}

#[cfg(test)]
mod tests;

/// The tests that train a policy to write (`crate::train`, `crate::test_support`): kept here,
/// beside the tests of the file alone, so that the module's own tests name no higher layer.
#[cfg(test)]
mod trained_tests {
    use std::ops::ControlFlow;

    use super::tests::{decode, tiny};
    use super::*;
    use crate::learn::tasks::pointmass as pt;

    /// Files with every payload that has per-core arrays: values in either precision,
    /// greedy actions of one to five varint bytes through each of the encoder's ways, arrays
    /// longer than its buffer, a learned model's tables and a model defined outside fuzzyq.
    fn payload_files() -> Vec<PolicyFile> {
        use crate::train::{ModelLearning, train_learned};

        // Runs of the encoder's buffer (2^16 values) of one to five bytes each: below 128,
        // below 16,384 (the bounds of one and two bytes among them), any, and a short last run.
        let n = 200_000;
        let greedy: Vec<u32> = (0..n as u32)
            .map(|i| match (i >> 16, i % 5) {
                (0, _) => i % 128,
                (1, 0) => 127,
                (1, 1) => 128,
                (1, 2) => 16_383,
                (1, _) => i % 16_384,
                (2, 0) => 1 << 20,
                (2, 1) => u32::MAX - i,
                (2, _) => 128 + i,
                _ => i % 200,
            })
            .collect();
        let mut a = tiny();
        a.values = Values::F32((0..n).map(|i| (i as f32).sin() * 1e3).collect());
        a.greedy = greedy.clone();
        let mut wide = a.clone();
        wide.values = Values::F64((0..n).map(|i| (i as f64).cos() / 7.0).collect());
        let mut config = tiny().config;
        config.grid.position_cores = vec![-1.0, 0.0, 1.0];
        let learned = train_learned(&config, &ModelLearning::new(500, 1), |_| {
            ControlFlow::Continue(())
        })
        .unwrap()
        .artifact;
        let tabulated = TabulatedArtifact {
            cores: vec![vec![-1.0, 1.0]; 2],
            membership: fuzzyq_core::Membership::Crisp,
            actions: vec![(vec![-1.0, 1.0], 1)],
            blocks: vec![(vec![0, 1], vec![0])],
            values: Values::F64(vec![0.5; n]),
            greedy,
            gamma: 0.9,
            xi: 0.01,
            absorbing_goal: true,
            summary: tiny().summary,
        };
        vec![
            PolicyFile::Fqi(a),
            PolicyFile::Fqi(wide),
            PolicyFile::Fqi(learned),
            PolicyFile::Fqi(tiny()),
            PolicyFile::Tabulated(Box::new(tabulated)),
        ]
    }

    /// The per-core arrays written in bulk ([`Content::encode`]) give serde's bytes, for
    /// every payload that has them ([`payload_files`]).
    #[test]
    fn every_payload_is_written_as_serde_encodes_it() {
        let serde = |file: &PolicyFile| {
            file.with_payload(|version, payload| {
                super::super::container::encode_postcard(&MAGIC, version, payload).unwrap()
            })
            .unwrap()
        };
        for (k, file) in payload_files().iter().enumerate() {
            let bytes = file.to_bytes().unwrap();
            assert_eq!(bytes, serde(file), "file {k}");
            let written = file.write_to(std::io::Cursor::new(Vec::new())).unwrap();
            assert_eq!(written.into_inner(), bytes, "file {k}, written as encoded");
        }
    }

    /// The per-core arrays read in bulk ([`Decode`]) give serde's values, and for a damaged
    /// payload serde's error, for every payload ([`payload_files`]; the checks:
    /// `container::assert_decoded_as_serde`).
    #[test]
    fn every_payload_is_read_as_serde_decodes_it() {
        for (k, file) in payload_files().iter().enumerate() {
            let bytes = file.to_bytes().unwrap();
            super::super::container::assert_decoded_as_serde::<Content<FqiPayload, BlockTables>>(
                &bytes[HEADER_LEN..],
                &format!("file {k}"),
            );
        }
    }

    /// Policies of a learned model written as version 3 (tables without their membership
    /// functions, then always triangular) still load, as triangular tables; version 4 keeps
    /// a crisp grid's tables crisp.
    #[test]
    fn version_3_learned_policies_still_load() {
        use crate::model::learned::BlockTable;
        use crate::train::{ModelLearning, train_learned};

        #[derive(Serialize)]
        struct BlockTablesV3Ref<'a> {
            cores: &'a [Vec<f64>],
            blocks: &'a [BlockTable],
        }
        let mut config = tiny().config;
        config.grid.position_cores = vec![-1.0, 0.0, 1.0];
        let run = train_learned(&config, &ModelLearning::new(500, 1), |_| {
            ControlFlow::Continue(())
        })
        .unwrap();
        let mut a = run.artifact;
        // What a file does not keep.
        (a.summary.setup_seconds, a.summary.result_seconds) = (None, None);
        let tables = a.learned.as_deref().unwrap();
        assert_eq!(tables.membership, fuzzyq_core::Membership::Triangular);
        let payload = postcard::to_stdvec(&Content::LearnedFqi(
            FqiPayloadRef {
                config_toml: a.config.to_toml(),
                values: &a.values,
                greedy: &a.greedy,
                summary: &a.summary,
            },
            BlockTablesV3Ref {
                cores: &tables.cores,
                blocks: &tables.blocks,
            },
        ))
        .unwrap();
        let v3 = super::super::container::encode(&MAGIC, 3, &payload);
        let file = PolicyFile::Fqi(a);
        assert_eq!(decode(&v3).unwrap(), file);
        assert_eq!(file.to_bytes().unwrap()[8], 4);

        config.grid.membership = fuzzyq_core::Membership::Crisp;
        let crisp = train_learned(&config, &ModelLearning::new(500, 1), |_| {
            ControlFlow::Continue(())
        })
        .unwrap()
        .artifact;
        let tables = crisp.learned.as_deref().unwrap();
        assert_eq!(tables.membership, fuzzyq_core::Membership::Crisp);
        let mut crisp = crisp;
        (crisp.summary.seconds, crisp.summary.sweep_seconds) = (0.0, 0.0);
        (crisp.summary.setup_seconds, crisp.summary.result_seconds) = (None, None);
        let file = PolicyFile::Fqi(crisp);
        assert_eq!(decode(&file.to_bytes().unwrap()).unwrap(), file);
        // The tables must match the configured grid's membership functions.
        let PolicyFile::Fqi(mut swapped) = file else {
            unreachable!()
        };
        swapped.learned.as_mut().unwrap().membership = fuzzyq_core::Membership::Triangular;
        let e = decode(&PolicyFile::Fqi(swapped).to_bytes().unwrap()).unwrap_err();
        assert!(e.to_string().contains("not on the configured grid"), "{e}");
    }

    #[test]
    fn point_mass_policy_files_round_trip_and_are_checked() {
        let go = |_: &crate::learn::fql::EpisodeRecord| ControlFlow::Continue(());
        let point_mass = |path: &Path| -> Result<PointMassPolicyFile, PolicyFileError> {
            match PolicyFile::load(path)? {
                PolicyFile::PointMass(f) => Ok(f),
                other => panic!("not a point-mass file: {other:?}"),
            }
        };
        let model = crate::test_support::tiny_model();
        let starts = crate::test_support::tiny_starts();
        let fql = FqlConfig {
            episodes: 30,
            ..crate::test_support::tiny_fql()
        };
        let features = pt::feature_space(&model, &[-6.0, 0.0, 6.0], &[-3.0, 0.0, 3.0]).unwrap();
        let out = pt::train_fql(&model, &features, &starts, &fql, go).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("pm.toml");
        let file = PointMassPolicyFile::from_outcome(model.config(), &starts, &fql, None, &out);
        PolicyFile::PointMass(file.clone()).save(&path).unwrap();
        let back = point_mass(&path).unwrap();
        assert_eq!(back, file);
        assert_eq!(back.episodes, 30);

        let vq = VqqlConfig {
            cells: 20,
            samples: 500,
            explore_steps: 20,
            ..VqqlConfig::default()
        };
        let (vout, _) = crate::learn::vqql::train_vqql(&model, &starts, &vq, &fql, go).unwrap();
        let vfile =
            PointMassPolicyFile::from_outcome(model.config(), &starts, &fql, Some(&vq), &vout);
        let vpath = dir.path().join("vq.toml");
        PolicyFile::PointMass(vfile.clone()).save(&vpath).unwrap();
        let vback = point_mass(&vpath).unwrap();
        assert_eq!(vback, vfile);
        assert!(vback.q.features().is_codebook());
        let (t1, _) = crate::test_support::rollout_additive(
            &model,
            &vback.q,
            &crate::test_support::TINY_X0,
            10,
            0.95,
        )
        .unwrap();
        let (t2, _) = crate::test_support::rollout_additive(
            &model,
            &vfile.q,
            &crate::test_support::TINY_X0,
            10,
            0.95,
        )
        .unwrap();
        assert_eq!(t1, t2);

        // Inconsistent files name the problem and the file.
        let load_err = |f: &PointMassPolicyFile| {
            std::fs::write(&path, toml::to_string(f).unwrap()).unwrap();
            point_mass(&path).unwrap_err().to_string()
        };
        let mut bad = file.clone();
        bad.vqql = Some(vq.clone());
        assert!(load_err(&bad).contains("needs codebook features"));
        let mut bad = vfile.clone();
        bad.vqql = None;
        assert!(load_err(&bad).contains("quantiser settings"));
        let mut bad = vfile.clone();
        bad.vqql = Some(VqqlConfig { cells: 21, ..vq });
        assert!(load_err(&bad).contains("vqql.cells = 21"));
        let mut bad = file.clone();
        bad.config.agents = 2;
        assert!(load_err(&bad).contains("has 1 agents"));
        let mut bad = file.clone();
        bad.config.force_levels = vec![-1.0, 1.0];
        assert!(load_err(&bad).contains("actions"));
        let mut bad = file.clone();
        bad.starts = Starts::Fixed(vec![0.0; 3]);
        assert!(load_err(&bad).contains("starts.fixed"));
        let mut bad = file.clone();
        bad.fql.gamma = 2.0;
        assert!(load_err(&bad).contains("fql.gamma"));
        std::fs::write(&path, "not = [toml").unwrap();
        let e = point_mass(&path).unwrap_err().to_string();
        assert!(
            e.contains("pm.toml") && e.contains("not a fuzzyq policy"),
            "{e}"
        );
        let e = point_mass(&dir.path().join("missing.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("cannot read"), "{e}");
    }

    /// A damaged policy learned from samples says what is wrong (line, field, value), and is
    /// told apart from a file that is no policy at all.
    #[test]
    fn damaged_toml_policies_say_what_is_wrong() {
        let model = crate::test_support::tiny_model();
        let starts = crate::test_support::tiny_starts();
        let fql = FqlConfig {
            episodes: 3,
            max_steps: 5,
            eval_every: 0,
            ..crate::test_support::tiny_fql()
        };
        let features = pt::feature_space(&model, &[-6.0, 0.0, 6.0], &[-3.0, 0.0, 3.0]).unwrap();
        let out = pt::train_fql(&model, &features, &starts, &fql, |_: &_| {
            ControlFlow::Continue(())
        })
        .unwrap();
        let file = PointMassPolicyFile::from_outcome(model.config(), &starts, &fql, None, &out);
        let text = toml::to_string(&file).unwrap();
        let read = |text: &str| PolicyFile::from_bytes(text.as_bytes(), Path::new("p.toml"));
        assert_eq!(read(&text).unwrap(), PolicyFile::PointMass(file));
        let line_of = |needle: &str| text[..text.find(needle).unwrap()].lines().count() + 1;
        let damaged = |text: &str| {
            let e = read(text).unwrap_err();
            assert!(matches!(e, PolicyFileError::Malformed { .. }), "{e}");
            let m = e.to_string();
            assert!(m.starts_with("p.toml is malformed: "), "{m}");
            assert!(!m.contains('\n'), "{m}");
            m
        };

        // Cut in the middle of the parameters, or at the end of a line.
        let phi = text.find("phi = [").unwrap();
        let m = damaged(&text[..phi + 20]);
        assert!(m.contains("truncated"), "{m}");
        assert!(
            m.ends_with(&format!("(line {})", line_of("phi = ["))),
            "{m}"
        );
        let m = damaged(&text[..phi]);
        assert!(m.contains("missing field `phi`"), "{m}");

        // A NaN names the field and its line; NaN (not TOML) is a syntax error on its line.
        let number = phi + text[phi..].find(|c: char| c.is_ascii_digit()).unwrap();
        let end = number + text[number..].find([',', ']']).unwrap();
        let with = |value: &str| format!("{}{value}{}", &text[..number], &text[end..]);
        let m = damaged(&with("nan"));
        assert!(
            m.contains("q.phi[0][0]: value is NaN")
                && m.ends_with(&format!("(line {})", line_of("phi = ["))),
            "{m}"
        );
        let m = damaged(&with("NaN"));
        assert!(m.contains("phi: ") && m.contains("(line "), "{m}");
        let m = damaged(&with("inf"));
        assert!(m.contains("finite"), "{m}");
        let m = damaged(&text.replace("episodes = ", "episodes = -"));
        assert!(m.contains("episodes") && m.contains("(line "), "{m}");

        // Not a policy at all.
        for other in [
            "",
            "hello",
            "not = [toml",
            "[env]\nkind = 1\n",
            crate::io::config::DEFAULT_POINTMASS_TOML,
        ] {
            let e = read(other).unwrap_err();
            assert!(
                matches!(e, PolicyFileError::NotAPolicy { .. }),
                "{other:?}: {e}"
            );
        }
        // Damaged beyond UTF-8.
        let mut bytes = text.clone().into_bytes();
        bytes[phi + 3] = 0xff;
        let e = PolicyFile::from_bytes(&bytes, Path::new("p.toml")).unwrap_err();
        assert!(e.to_string().contains("not UTF-8"), "{e}");
    }
}
