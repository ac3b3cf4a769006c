//! How each agent's observation becomes active cells: fuzzy partitions (the paper's
//! triangular grids) or crisp codebooks (VQQL's vector quantisers).

use std::fmt;

use fuzzyq_core::partition::{ActiveCores, ProductPartition};
use fuzzyq_core::{EvalError, MAX_DIMS};
use serde::de::value::{MapAccessDeserializer, SeqAccessDeserializer};
use serde::de::{self, MapAccess, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer, Serialize, Serializer};

use crate::error::{ConfigError, SimError, require};
use crate::learn::codebook::Codebook;

/// How every agent's observation is turned into active cells: fuzzy partitions (the paper's
/// triangular grids) or crisp codebooks (vector quantisers, for VQQL). All agents use the same
/// kind.
///
/// - Fuzzy ([`FeatureSpace::new`]): per agent, the cores of each observation dimension,
///   validated as a product partition; the active cores of an observation are its at most
///   `2^E` cores with non-zero membership. Serialised as the nested core lists
///   (`[agent][dimension][core]`), the format of every fuzzy policy file.
/// - Codebook ([`FeatureSpace::codebook`]): per agent a [`Codebook`]; the active set of an
///   observation is the single cell of its nearest centroid with membership 1
///   ([`ActiveCores::single`]). Serialised as a table `{ codebooks = [...] }`.
///
/// Deserialising accepts either form and validates it.
#[derive(Clone, Debug, PartialEq)]
pub struct FeatureSpace {
    pub(crate) kind: FeatureKind,
    pub(crate) n_cores: Vec<usize>,
}

/// The two kinds of features (see [`FeatureSpace`]).
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum FeatureKind {
    Fuzzy(Vec<Vec<Vec<f64>>>),
    Codebook(Vec<Codebook>),
}

/// Builds the product partition of agent `agent`'s cores (at most [`MAX_DIMS`] dimensions);
/// errors name `features[agent]`.
fn grid_of(agent: usize, cores: &[Vec<f64>]) -> Result<ProductPartition<'_, f64>, SimError> {
    let field = || format!("features[{agent}]");
    require!(
        cores.len() <= MAX_DIMS,
        field(),
        format!(
            "an observation has at most {MAX_DIMS} dimensions, found {}",
            cores.len()
        ),
    );
    let mut refs: [&[f64]; MAX_DIMS] = [&[]; MAX_DIMS];
    for (r, c) in refs.iter_mut().zip(cores) {
        *r = c.as_slice();
    }
    ProductPartition::try_new(&refs[..cores.len()])
        .map_err(|e| ConfigError::invalid(field(), e.to_string()).into())
}

impl FeatureSpace {
    /// Validates `per_agent_cores[i][e]`, the sorted cores of observation dimension `e` of
    /// agent `i` (at least one agent; per agent 1 to [`MAX_DIMS`] dimensions of at least two
    /// finite, strictly increasing cores). Errors name the agent (`features[i]`).
    pub fn new(per_agent_cores: Vec<Vec<Vec<f64>>>) -> Result<Self, SimError> {
        if per_agent_cores.is_empty() {
            return Err(ConfigError::invalid("features", "needs at least one agent").into());
        }
        let mut n_cores = Vec::with_capacity(per_agent_cores.len());
        for (i, cores) in per_agent_cores.iter().enumerate() {
            n_cores.push(grid_of(i, cores)?.n_cores());
        }
        Ok(Self {
            kind: FeatureKind::Fuzzy(per_agent_cores),
            n_cores,
        })
    }

    /// Crisp features: agent `i` quantises its observation with `codebooks[i]` (at least one
    /// agent). Its "cores" are the codebook's cells, and the additive Q-function over them is
    /// a table: [`learn`](crate::learn::fql::learn) then runs tabular Q-learning (see
    /// "Codebook features" in [`fql`](crate::learn::fql)).
    pub fn codebook(codebooks: Vec<Codebook>) -> Result<Self, SimError> {
        if codebooks.is_empty() {
            return Err(ConfigError::invalid("features", "needs at least one agent").into());
        }
        let n_cores = codebooks.iter().map(Codebook::n_cells).collect();
        Ok(Self {
            kind: FeatureKind::Codebook(codebooks),
            n_cores,
        })
    }

    /// Number of agents.
    #[must_use]
    pub fn n_agents(&self) -> usize {
        self.n_cores.len()
    }

    /// Whether the features are codebooks (crisp cells) rather than fuzzy partitions.
    #[must_use]
    pub fn is_codebook(&self) -> bool {
        matches!(self.kind, FeatureKind::Codebook(_))
    }

    /// The fuzzy cores, `[agent][dimension][core]`; empty for codebook features.
    #[must_use]
    pub fn cores(&self) -> &[Vec<Vec<f64>>] {
        match &self.kind {
            FeatureKind::Fuzzy(cores) => cores,
            FeatureKind::Codebook(_) => &[],
        }
    }

    /// The codebooks, one per agent; empty for fuzzy features.
    #[must_use]
    pub fn codebooks(&self) -> &[Codebook] {
        match &self.kind {
            FeatureKind::Fuzzy(_) => &[],
            FeatureKind::Codebook(books) => books,
        }
    }

    /// Observation length of agent `agent`, or `None` if there is no such agent.
    #[must_use]
    pub fn obs_dim(&self, agent: usize) -> Option<usize> {
        match &self.kind {
            FeatureKind::Fuzzy(cores) => cores.get(agent).map(Vec::len),
            FeatureKind::Codebook(books) => books.get(agent).map(Codebook::dim),
        }
    }

    /// Number of joint cores `N_i` of agent `agent` (cells, for a codebook), or `None` if
    /// there is no such agent.
    #[must_use]
    pub fn n_cores(&self, agent: usize) -> Option<usize> {
        self.n_cores.get(agent).copied()
    }

    /// The product partition of agent `agent` (row-major core order, see
    /// [`fuzzyq_core::partition`]). Fails for codebook features.
    pub fn grid(&self, agent: usize) -> Result<ProductPartition<'_, f64>, SimError> {
        let cores = match &self.kind {
            FeatureKind::Fuzzy(cores) => cores,
            FeatureKind::Codebook(_) => {
                return Err(ConfigError::invalid(
                    "features",
                    "codebook features have no fuzzy grid",
                )
                .into());
            }
        };
        let cores = cores.get(agent).ok_or(EvalError::OutOfRange {
            what: "agent",
            index: agent,
            len: cores.len(),
        })?;
        grid_of(agent, cores)
    }

    pub(crate) fn grids(&self) -> Result<Vec<ProductPartition<'_, f64>>, SimError> {
        (0..self.n_agents()).map(|i| self.grid(i)).collect()
    }

    /// The active cores of agent `agent` at its observation `obs` (checked length, finite
    /// values): the fuzzy cores with non-zero membership, or the nearest codebook cell with
    /// membership 1.
    pub fn active(&self, agent: usize, obs: &[f64]) -> Result<ActiveCores<f64>, SimError> {
        let observation = |e: EvalError| match e {
            EvalError::Length {
                expected, found, ..
            } => EvalError::Length {
                what: "observation",
                expected,
                found,
            },
            EvalError::NotFinite { index, .. } => EvalError::NotFinite {
                what: "observation",
                index,
            },
            other => other,
        };
        match &self.kind {
            FeatureKind::Fuzzy(_) => {
                let grid = self.grid(agent)?;
                Ok(grid.active(obs).map_err(observation)?)
            }
            FeatureKind::Codebook(books) => {
                let book = books.get(agent).ok_or(EvalError::OutOfRange {
                    what: "agent",
                    index: agent,
                    len: books.len(),
                })?;
                Ok(ActiveCores::single(book.nearest(obs)?))
            }
        }
    }

    /// Number of parameters `sum_i N_i * M_i` of the additive layout for `actions[i] = M_i`
    /// actions per agent (one count per agent, each `>= 1`).
    pub fn n_params(&self, actions: &[usize]) -> Result<usize, SimError> {
        require!(
            actions.len() == self.n_agents(),
            "actions",
            format!(
                "expected one action count per agent ({}), found {}",
                self.n_agents(),
                actions.len()
            ),
        );
        let mut total = 0usize;
        for (i, (&m, &n)) in actions.iter().zip(&self.n_cores).enumerate() {
            require!(
                m != 0,
                &format!("actions[{i}]"),
                "an agent needs at least one action",
            );
            total = n
                .checked_mul(m)
                .and_then(|p| total.checked_add(p))
                .ok_or_else(|| ConfigError::invalid("features", "too many parameters"))?;
        }
        Ok(total)
    }
}

/// The serialised form of codebook features.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct CodebookFeatures<B> {
    codebooks: B,
}

impl Serialize for FeatureSpace {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match &self.kind {
            FeatureKind::Fuzzy(cores) => cores.serialize(s),
            FeatureKind::Codebook(books) => CodebookFeatures { codebooks: books }.serialize(s),
        }
    }
}

impl<'de> Deserialize<'de> for FeatureSpace {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Either;
        impl<'de> Visitor<'de> for Either {
            type Value = FeatureSpace;
            fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str("fuzzy cores [agent][dimension][core] or a table { codebooks = [...] }")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, seq: A) -> Result<Self::Value, A::Error> {
                let cores = Vec::<Vec<Vec<f64>>>::deserialize(SeqAccessDeserializer::new(seq))?;
                FeatureSpace::new(cores).map_err(de::Error::custom)
            }
            fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Self::Value, A::Error> {
                let data = CodebookFeatures::<Vec<Codebook>>::deserialize(
                    MapAccessDeserializer::new(map),
                )?;
                FeatureSpace::codebook(data.codebooks).map_err(de::Error::custom)
            }
        }
        d.deserialize_any(Either)
    }
}

/// How [`learn`] and [`evaluate`] find the active cells of an observation the learner has
/// already checked (right length, finite): monomorphised per feature kind, so the fuzzy path
/// is the plain grid lookup.
pub(crate) trait Lookup {
    fn n_dims(&self) -> usize;
    fn lookup(&self, obs: &[f64]) -> ActiveCores<f64>;
}

impl Lookup for ProductPartition<'_, f64> {
    #[inline]
    fn n_dims(&self) -> usize {
        ProductPartition::n_dims(self)
    }
    #[inline]
    fn lookup(&self, obs: &[f64]) -> ActiveCores<f64> {
        self.active_unchecked(obs)
    }
}

impl Lookup for Codebook {
    #[inline]
    fn n_dims(&self) -> usize {
        self.dim()
    }
    #[inline]
    fn lookup(&self, obs: &[f64]) -> ActiveCores<f64> {
        ActiveCores::single(self.nearest_unchecked(obs).0)
    }
}
