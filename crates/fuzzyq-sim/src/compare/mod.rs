//! The paper's Table 1, rerun: several learners on one point-mass task, every policy rolled
//! out from the same start and from the same seeded random starts.
//!
//! Section 4 of the paper compares its fuzzy learner with CMOMMT (a crisp state-aggregation
//! learner) from the start [`paper::TABLE1_X0`] and reports final error, time to goal and
//! iterations. [`compare`] trains each [`Learner`] on the task of one [`TrainConfig`] (same
//! model, actions, reward, discount and, where a grid applies, the same cores), then measures:
//!
//! - from [`CompareConfig::x0`]: the greedy rollout's final distance of each agent to the
//!   goal and the time the reward region (`||x||_2 < 0.1` over the whole state) is first
//!   reached;
//! - over [`CompareConfig::starts`] random starts at rest (drawn once, the same for every
//!   learner): the success rate (reward region reached within the rollout), the mean time to
//!   it over the successes and the mean final error;
//! - the work: iterations and what one counts (a synchronous sweep over every core for the
//!   model-based learners, an episode for the model-free ones), wall-clock training seconds,
//!   and the number of parameters of the Q-function each learner represents.
//!
//! | learner | what it is | parameters |
//! |---|---|---|
//! | [`Learner::Fqi`] | joint fuzzy Q-iteration (the paper's method, [`crate::train`]) | `N * M` (cores x joint actions); only `V` is stored |
//! | [`Learner::Crisp`] | grid Q-iteration on the same cores as crisp nearest-core boxes ([`fuzzyq_core::Membership::Crisp`]) | `N * M` |
//! | [`Learner::CrispUniform`] | the same on boxes evenly spaced over each variable's range, as many per variable as the grid has cores ([`uniform_cores`]): boxes a step can leave | `N * M` |
//! | [`Learner::Fql`] | fuzzy Q-learning, additive layout, corrected update ([`crate::learn::fql`]) | `sum_i N_i * M_i` |
//! | [`Learner::FqlLiteral`] | the same with the update as printed (eqs 24-26) | `sum_i N_i * M_i` |
//! | [`Learner::Vqql`] | VQQL, the CMOMMT learner: k-means cells per agent + tabular Q-learning ([`crate::learn::vqql`]) | `sum_i K_i * M_i` |
//! | [`Learner::LearnedModel`] | joint fuzzy Q-iteration on a fuzzy model learned from transitions collected on the plant ([`crate::train::train_learned`]) | `N * M`; only `V` and the learned tables are stored |
//! | [`Learner::FqiSamples`] | fuzzy Q-iteration from samples: batch fitted Q-iteration with the fuzzy averager, per agent, on [`CompareConfig::batch`]'s transitions, never building a model ([`crate::learn::fitted`]) | `sum_i N_i * M_i` |
//! | [`Learner::VqqlBatch`] | its crisp counterpart: VQQL's k-means cells, fitted Q-iteration over them on the same transitions | `sum_i K_i * M_i` |
//!
//! [`sample_efficiency`] asks the other question of Table 1, at equal samples: each learner
//! from samples (the learned model, fuzzy Q-learning, VQQL) gets the same numbers of
//! transitions of interaction ([`with_budget`]) and is measured over the same random starts.
//!
//! # Rewards, seeds and the codebook sweep
//! - The reward is the task's ([`PointMassConfig::reward`](crate::PointMassConfig::reward)):
//!   the paper's, or the same with a potential-based shaping term
//!   ([`CompareConfig::set_reward`]). The learners from samples learn from it. The
//!   learners that plan with the model plan with the paper's reward under either: shaping by
//!   the potential as their grid represents it (interpolated from its values at the cores)
//!   leaves their solution the paper's minus `Phi` at each core, so their greedy policy is the
//!   same (Ng, Harada and Russell 1999, on the grid's own Markov chain), while shaping by the
//!   exact potential makes the reward depend on the joint action at each of the grid's
//!   `N * M` pairs in every full backup (measured: 239 s per full backup on the paper's grid,
//!   2 cores, against about 0.2 s).
//! - With [`CompareConfig::seeds`] above 1 every learner from samples runs once per seed
//!   (`seed`, `seed + 1`, ...): the table gives the means over seeds with 95% percentile
//!   bootstrap intervals ([`Estimate`]), and the paths of every seed.
//! - With [`CompareConfig::vqql_sweep`] VQQL runs once per codebook size (and seed); the
//!   sweep is reported whole ([`SweepPoint`]) and the table's VQQL column is the best size:
//!   the highest mean success over the random starts, then the lowest mean final error over
//!   them (never the Table 1 start itself, which the table reports).
//!
//! Everything is seeded: the same configuration gives the same table (bar the seconds).

use std::time::Instant;

use fuzzyq_core::Membership;
use fuzzyq_core::additive::Update;
use fuzzyq_core::q::PolicyKind;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError, require};
use crate::io::config::{EnvConfig, TrainConfig};
use crate::io::policy_file::{PolicyArtifact, Values};
use crate::learn::additive::AdditiveQ;
use crate::learn::fitted::{self, FittedConfig};
use crate::learn::fql::FqlConfig;
use crate::learn::samples::{Collection, Exploration};
use crate::learn::tasks::pointmass as pointmass_task;
use crate::learn::vqql::{self, VqqlConfig};
use crate::model::classic::octave::linspace;
use crate::model::pointmass::{self, PointMass, RewardShape, Starts};
use crate::model::{EnvModel, F64Model, check_state};
use crate::paper;
use crate::run::evaluate::{self, Outcome, PlantChoice, RolloutSpec};
use crate::run::metrics::{PointMassReport, RolloutMetrics, Trajectory, mean_final_error_cm};
use crate::run::policy::{AdditivePolicy, FqiPolicy, Policy};
use crate::train::{self, ModelLearning, SampleLearning};

fuzzyq_core::named_option! {
    /// A learner of the comparison (a column of the table).
    pub enum Learner: "learner" {
        /// Joint fuzzy Q-iteration on the configured grid (the paper's method).
        Fqi = "fqi" => "joint fuzzy Q-iteration (the paper's method)",
        /// Grid Q-iteration on the same cores as crisp nearest-core boxes.
        Crisp = "crisp" => "grid Q-iteration, same cores as crisp boxes",
        /// Grid Q-iteration on crisp boxes evenly spaced over each variable's range, as many
        /// per variable as the grid has cores.
        CrispUniform = "crisp-uniform" => "grid Q-iteration, as many crisp boxes evenly spaced",
        /// Fuzzy Q-learning, additive layout, corrected update.
        Fql = "fql" => "fuzzy Q-learning, additive layout, corrected update",
        /// Fuzzy Q-learning, additive layout, the update as printed in the paper.
        FqlLiteral = "fql-literal" => "fuzzy Q-learning, additive layout, update as printed",
        /// VQQL: per-agent k-means cells and tabular Q-learning (CMOMMT's learner).
        Vqql = "vqql" => "VQQL (CMOMMT): k-means cells + tabular Q-learning",
        /// Joint fuzzy Q-iteration on a fuzzy model learned from transitions.
        LearnedModel = "learned-model" => "joint fuzzy Q-iteration on a model learned from transitions",
        /// Fuzzy Q-iteration from samples: fitted Q-iteration with the fuzzy averager, per
        /// agent, on a batch of transitions, with no model.
        FqiSamples = "fqi-samples" => "fuzzy Q-iteration from samples (fitted, per agent, no model)",
        /// VQQL from a batch: VQQL's k-means cells, and fitted Q-iteration over them (a crisp
        /// averager) on the same transitions as `fqi-samples`.
        VqqlBatch = "vqql-batch" => "VQQL cells + fitted Q-iteration on the same transitions (crisp, batch)",
    }
}

impl Learner {
    /// A one-line description.
    #[must_use]
    pub fn description(self) -> &'static str {
        fuzzyq_core::NamedOption::help(self)
    }

    /// Parses a [`name`](Self::name); the error names the `learners` field.
    pub fn parse(name: &str) -> Result<Self, ConfigError> {
        name.parse()
            .map_err(|e| ConfigError::invalid("learners", format!("{name:?}: {e}")))
    }

    /// Whether the learner is one of VQQL's (k-means cells, swept by
    /// [`CompareConfig::vqql_sweep`]).
    #[must_use]
    pub fn is_vqql(self) -> bool {
        matches!(self, Self::Vqql | Self::VqqlBatch)
    }

    /// Whether the learner is model-based (iterates over a grid with the model).
    #[must_use]
    pub fn is_model_based(self) -> bool {
        matches!(
            self,
            Self::Fqi | Self::Crisp | Self::CrispUniform | Self::LearnedModel
        )
    }
}

/// What [`compare`] runs.
#[derive(Clone, Debug, PartialEq)]
pub struct CompareConfig {
    /// The task: a point-mass environment, the grid of the grid-based learners and the
    /// solver settings (its `gamma` is every learner's discount).
    pub task: TrainConfig,
    /// The start of the single rollout (the paper's Table 1 start by default).
    pub x0: Vec<f64>,
    /// Rollout length in sample times, for the single rollout and the random starts.
    pub steps: usize,
    /// Number of random starts.
    pub starts: usize,
    /// Seed of the random starts.
    pub seed: u64,
    /// Random starts put each agent uniformly in `[-start_position, start_position]^2`, at rest.
    pub start_position: f64,
    /// The learners, in table order (no repeats).
    pub learners: Vec<Learner>,
    /// Fuzzy Q-learning settings (both FQL learners and the Q-learning of VQQL; the update
    /// is set per learner and the discount is the task's).
    pub fql: FqlConfig,
    /// Where the model-free learners' episodes start.
    pub fql_starts: Starts,
    /// VQQL's quantiser.
    pub vqql: VqqlConfig,
    /// The learned-model learner's interaction with the plant and fit (its seed is the
    /// fuzzy Q-learning seed's).
    pub model_learning: ModelLearning,
    /// The batch learners' ([`Learner::FqiSamples`], [`Learner::VqqlBatch`]) transitions:
    /// random actions on the plant, as the learned model collects them (by default 100,000
    /// in episodes of the learned model's length, its seed).
    pub batch: Collection,
    /// Runs of every learner from samples, seeded `fql.seed`, `fql.seed + 1`, ... (the
    /// learned model's collection and VQQL's exploration likewise); 1 to 100.
    pub seeds: usize,
    /// VQQL codebook sizes (cells per agent) to sweep, the best one making the VQQL column;
    /// empty: [`VqqlConfig::cells`] alone.
    pub vqql_sweep: Vec<usize>,
}

impl Default for CompareConfig {
    /// [`CompareConfig::new`] on the paper's task and grid.
    fn default() -> Self {
        Self::new(TrainConfig::default())
    }
}

impl CompareConfig {
    /// The comparison on `task`: the Table 1 start, 100 random starts (seed 7) within 5 m of
    /// the goal, 100 steps (40 s) per rollout, every learner with its defaults, one seed, and
    /// VQQL swept over [`default_sweep`] of the task's own-state cores (`n_pos^2 * n_vel^2`),
    /// its single size ([`VqqlConfig::cells`]) being that count, so that its table has
    /// exactly as many parameters as the additive fuzzy layout.
    #[must_use]
    pub fn new(task: TrainConfig) -> Self {
        let own_cores =
            task.grid.position_cores.len().pow(2) * task.grid.velocity_cores.len().pow(2);
        let vqql = VqqlConfig {
            cells: own_cores,
            ..VqqlConfig::default()
        };
        Self {
            task,
            x0: paper::TABLE1_X0.to_vec(),
            steps: 100,
            starts: 100,
            seed: 7,
            start_position: crate::model::pointmass::START_POSITION,
            learners: <Learner as fuzzyq_core::NamedOption>::ALL.to_vec(),
            fql: pointmass_task::default_fql_config(),
            fql_starts: pointmass_task::default_starts(),
            vqql,
            model_learning: ModelLearning::new(20_000, pointmass_task::default_fql_config().seed),
            batch: Collection {
                samples: 100_000,
                ..ModelLearning::new(1, pointmass_task::default_fql_config().seed).collection
            },
            seeds: 1,
            vqql_sweep: default_sweep(own_cores),
        }
    }

    /// The task's reward ([`RewardShape`]).
    #[must_use]
    pub fn reward(&self) -> RewardShape {
        match &self.task.env {
            EnvConfig::Pointmass(p) => p.reward,
            _ => RewardShape::Paper,
        }
    }

    /// Sets the task's reward, the shaping discounted with the task's `gamma`.
    pub fn set_reward(&mut self, reward: RewardShape) {
        let gamma = self.task.solver.gamma;
        if let EnvConfig::Pointmass(p) = &mut self.task.env {
            p.reward = reward;
            p.shaping_discount = gamma;
        }
    }

    /// The task the learners that plan with the model solve: the paper's reward (see the
    /// [module docs](self#rewards-seeds-and-the-codebook-sweep)).
    fn planning_task(&self) -> TrainConfig {
        let mut task = self.task.clone();
        if let EnvConfig::Pointmass(p) = &mut task.env {
            p.reward = RewardShape::Paper;
            p.shaping_discount = paper::GAMMA;
        }
        task
    }

    /// This configuration with seed `seed` for every learner from samples.
    fn with_seed(&self, seed: u64) -> Self {
        let mut c = self.clone();
        c.fql.seed = seed;
        c.vqql.seed = seed;
        c.model_learning.collection.seed = seed;
        c.batch.seed = seed;
        c
    }

    /// Checks the configuration; errors name the field.
    pub fn validate(&self) -> Result<(), SimError> {
        self.task.validate()?;
        let model = self.model()?;
        check_state(&model, &self.x0)?;
        if self.steps == 0 {
            return Err(ConfigError::invalid("steps", "must be at least 1").into());
        }
        if self.starts == 0 {
            return Err(ConfigError::invalid("starts", "must be at least 1").into());
        }
        if self.learners.is_empty() {
            return Err(ConfigError::invalid("learners", "name at least one learner").into());
        }
        for (i, l) in self.learners.iter().enumerate() {
            require!(
                !self.learners[..i].contains(l),
                "learners",
                format!("{} is named twice", l.name()),
            );
        }
        let bound = pointmass_bound(&model);
        require!(
            self.start_position > 0.0 && self.start_position <= bound,
            "start_position",
            format!(
                "must be in (0, {bound}] (the position range), got {}",
                self.start_position
            ),
        );
        self.fql.validate()?;
        self.fql_starts.validate(&model)?;
        if self.learners.contains(&Learner::LearnedModel) {
            self.model_learning.collection.validate()?;
        }
        if self.learners.contains(&Learner::FqiSamples)
            || self.learners.contains(&Learner::VqqlBatch)
        {
            self.batch
                .validate()
                .map_err(|e| ConfigError::invalid("batch", e.to_string()))?;
        }
        if self.learners.iter().any(|l| l.is_vqql()) {
            self.vqql.validate()?;
            for &cells in &self.vqql_sweep {
                VqqlConfig {
                    cells,
                    ..self.vqql.clone()
                }
                .validate()
                .map_err(|e| ConfigError::invalid("vqql_sweep", e.to_string()))?;
            }
        }
        require!(
            (1..=100).contains(&self.seeds),
            "seeds",
            format!("must be between 1 and 100, got {}", self.seeds),
        );
        Ok(())
    }

    fn model(&self) -> Result<PointMass, SimError> {
        match &self.task.env {
            EnvConfig::Pointmass(p) => Ok(PointMass::new(p.clone())?),
            other => Err(ConfigError::invalid(
                "env",
                format!(
                    "the comparison runs on the point-mass task, not {}",
                    other.name()
                ),
            )
            .into()),
        }
    }
}

/// The VQQL codebook sizes swept by default: the powers of two from 16 below `cores` (the
/// fuzzy grid's own-state cores per agent), then `cores` itself (as many cells as cores).
#[must_use]
pub fn default_sweep(cores: usize) -> Vec<usize> {
    let mut sizes: Vec<usize> = (4..usize::BITS)
        .map(|b| 1usize << b)
        .take_while(|&k| k < cores)
        .collect();
    sizes.push(cores);
    sizes
}

/// The largest position magnitude of the model's state space.
fn pointmass_bound(model: &PointMass) -> f64 {
    let (lo, hi) = fuzzyq_core::Model::<f64>::state_bounds(model, 0);
    lo.abs().min(hi.abs())
}

/// One learner's row of the table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LearnerReport {
    /// The learner.
    pub learner: Learner,
    /// What it is.
    pub description: String,
    /// Iterations performed.
    pub iterations: usize,
    /// What one iteration is: `"sweeps"` (over every core) or `"episodes"`.
    pub iteration_unit: String,
    /// Whether the learner's stopping rule was met (`||theta_{k+1} - theta_k|| <= xi` for the
    /// iterations; the windowed eq-27 test for the learners from samples).
    pub converged: bool,
    /// Wall-clock training seconds (model tables or exploration included).
    pub train_seconds: f64,
    /// Parameters of the Q-function the learner represents.
    pub parameters: u64,
    /// Values it keeps in memory for its policy (`V` per core for the iterations; the
    /// parameters, plus the codebook for VQQL).
    pub stored_values: u64,
    /// The greedy rollout from [`CompareConfig::x0`].
    pub from_x0: RolloutMetrics,
    /// Mean over agents of the final distance to the goal from `x0` (cm).
    pub final_error_cm: f64,
    /// First time in the reward region from `x0` (s).
    pub time_to_goal_s: Option<f64>,
    /// Fraction of the random starts that reach the reward region.
    pub success_rate: f64,
    /// Mean time to the reward region over the successful random starts (s).
    pub mean_time_to_goal_s: Option<f64>,
    /// Mean over random starts and agents of the final distance to the goal (cm).
    pub mean_final_error_cm: f64,
    /// Learner-specific notes (k-means iterations and distortion for VQQL, ...).
    pub notes: Vec<String>,
    /// The largest parameter magnitude of a learner from samples (over its seeds).
    pub largest_parameter: Option<f64>,
    /// Over several seeds ([`CompareConfig::seeds`] > 1, learners from samples): the means
    /// with their intervals. The fields above then hold the means (the rollout `from_x0` is
    /// the first seed's).
    pub over_seeds: Option<OverSeeds>,
}

impl LearnerReport {
    /// Records a learner's per-agent Q-function: its parameters (kept in memory too) and the
    /// largest magnitude among them, which it returns.
    fn record_parameters(&mut self, q: &AdditiveQ) -> f64 {
        self.parameters = q.params().iter().map(|p| p.len() as u64).sum();
        self.stored_values += self.parameters;
        let largest = q
            .params()
            .iter()
            .flatten()
            .fold(0.0_f64, |m, p| m.max(p.abs()));
        self.largest_parameter = Some(largest);
        largest
    }

    /// Records VQQL's codebook of `cells` cells per agent: a note and its stored values.
    fn record_codebook(&mut self, cells: usize, lloyd: &vqql::LloydReport) {
        self.notes.push(format!(
            "k-means: {cells} cells per agent, {} Lloyd iterations, distortion {:.4}",
            lloyd.iterations, lloyd.distortion
        ));
        self.stored_values += lloyd.codebook_values as u64;
    }
}

/// A mean over seeds with its 95% percentile bootstrap interval ([`bootstrap`]).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// The mean.
    pub mean: f64,
    /// The interval's lower end.
    pub lo: f64,
    /// The interval's upper end.
    pub hi: f64,
}

/// A learner's measurements over its seeds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OverSeeds {
    /// The seeds, in run order.
    pub seeds: Vec<u64>,
    /// Final error from `x0` (cm, mean of the agents), per seed.
    pub final_error_cm: Vec<f64>,
    /// Time to the reward region from `x0` (s), per seed (`None`: never).
    pub time_to_goal_s: Vec<Option<f64>>,
    /// Success over the random starts, per seed.
    pub success_rate: Vec<f64>,
    /// Mean final error over the random starts (cm), per seed.
    pub mean_final_error_cm: Vec<f64>,
    /// [`final_error_cm`](Self::final_error_cm) over the seeds.
    pub final_error: Estimate,
    /// Time to goal over the seeds that reach the goal from `x0` (`None` if none does).
    pub time_to_goal: Option<Estimate>,
    /// [`success_rate`](Self::success_rate) over the seeds.
    pub success: Estimate,
    /// [`mean_final_error_cm`](Self::mean_final_error_cm) over the seeds.
    pub mean_final_error: Estimate,
}

/// One codebook size of the VQQL sweep ([`CompareConfig::vqql_sweep`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SweepPoint {
    /// The VQQL learner swept ([`Learner::Vqql`] or [`Learner::VqqlBatch`]).
    pub learner: Learner,
    /// Cells per agent.
    pub cells: usize,
    /// Parameters of the Q-table (all agents).
    pub parameters: u64,
    /// The measurements over the seeds (one seed: intervals of width 0).
    pub over_seeds: OverSeeds,
    /// The best size (the table's VQQL column).
    pub best: bool,
}

/// The mean of `values` and the 95% percentile bootstrap interval of the mean: 10,000
/// resamples with replacement drawn from `Pcg64Mcg` seeded with `seed`, the 2.5% and 97.5%
/// order statistics of their means. `None` for no values.
#[must_use]
pub fn bootstrap(values: &[f64], seed: u64) -> Option<Estimate> {
    const RESAMPLES: usize = 10_000;
    let n = values.len();
    if n == 0 {
        return None;
    }
    let mean = values.iter().sum::<f64>() / n as f64;
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let mut means: Vec<f64> = (0..RESAMPLES)
        .map(|_| (0..n).map(|_| values[rng.random_range(0..n)]).sum::<f64>() / n as f64)
        .collect();
    means.sort_by(f64::total_cmp);
    let at = |q: f64| means[((q * RESAMPLES as f64) as usize).min(RESAMPLES - 1)];
    Some(Estimate {
        mean,
        lo: at(0.025),
        hi: at(0.975),
    })
}

impl OverSeeds {
    /// The measurements of `runs` (one report per seed) with their bootstrap intervals.
    fn of(seeds: Vec<u64>, runs: &[LearnerReport]) -> Self {
        let col = |f: &dyn Fn(&LearnerReport) -> f64| runs.iter().map(f).collect::<Vec<_>>();
        let (final_error_cm, success_rate, mean_final_error_cm) = (
            col(&|r| r.final_error_cm),
            col(&|r| r.success_rate),
            col(&|r| r.mean_final_error_cm),
        );
        let time_to_goal_s: Vec<Option<f64>> = runs.iter().map(|r| r.time_to_goal_s).collect();
        let reached: Vec<f64> = time_to_goal_s.iter().flatten().copied().collect();
        let est = |v: &[f64]| bootstrap(v, BOOTSTRAP_SEED).expect("at least one seed");
        Self {
            final_error: est(&final_error_cm),
            time_to_goal: bootstrap(&reached, BOOTSTRAP_SEED),
            success: est(&success_rate),
            mean_final_error: est(&mean_final_error_cm),
            seeds,
            final_error_cm,
            time_to_goal_s,
            success_rate,
            mean_final_error_cm,
        }
    }
}

/// The seed of every bootstrap of the table (intervals are part of the seeded output).
const BOOTSTRAP_SEED: u64 = 0x7ab1e1;

/// The outcome of [`compare`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// The start of the single rollout.
    pub x0: Vec<f64>,
    /// Rollout length in sample times.
    pub steps: usize,
    /// Sample time (s).
    pub dt: f64,
    /// Number of random starts.
    pub starts: usize,
    /// Their seed.
    pub seed: u64,
    /// Their position range.
    pub start_position: f64,
    /// One report per learner, in the configured order.
    pub reports: Vec<LearnerReport>,
    /// The rollout from `x0` of each learner, in the same order (the first seed's).
    pub trajectories: Vec<Trajectory>,
    /// The rollouts from `x0` of each learner's further seeds, in the same order (empty for
    /// the learners that run once).
    pub seed_trajectories: Vec<Vec<Trajectory>>,
    /// The task's reward.
    pub reward: RewardShape,
    /// The VQQL codebook sweep (empty without one).
    pub vqql_sweep: Vec<SweepPoint>,
}

/// What [`compare`] is doing, for progress output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// A learner starts training.
    Training(Learner),
    /// A learner has trained: `(learner, iterations, seconds)`.
    Trained(Learner, usize, f64),
    /// A learner's policy is rolled out from the random starts.
    Evaluating(Learner),
    /// A learner from samples starts its run with `seed` (with `cells` per agent for VQQL),
    /// when it runs more than once.
    Run {
        /// The learner.
        learner: Learner,
        /// The run's seed.
        seed: u64,
        /// VQQL's codebook size.
        cells: Option<usize>,
    },
}

/// Trains every configured learner and measures its greedy policy (see the
/// [module docs](self)). `progress` sees what is running.
pub fn compare(
    config: &CompareConfig,
    mut progress: impl FnMut(Event),
) -> Result<Comparison, SimError> {
    config.validate()?;
    let model = config.model()?;
    let starts =
        pointmass::random_starts(&model, config.starts, config.seed, config.start_position)?;
    let spec = RolloutSpec {
        kind: PolicyKind::Greedy,
        steps: config.steps,
        plant: PlantChoice::Model,
        seed: 0,
    };
    let mut out = Comparison {
        x0: config.x0.clone(),
        steps: config.steps,
        dt: model.config().sample_time,
        starts: config.starts,
        seed: config.seed,
        start_position: config.start_position,
        reports: Vec::with_capacity(config.learners.len()),
        trajectories: Vec::with_capacity(config.learners.len()),
        seed_trajectories: Vec::with_capacity(config.learners.len()),
        reward: config.reward(),
        vqql_sweep: Vec::new(),
    };
    let mut progress: &mut dyn FnMut(Event) = &mut progress;
    for &learner in &config.learners {
        let (report, mut paths) = if learner.is_model_based() && learner != Learner::LearnedModel {
            let (report, path) = measure(config, learner, &starts, &spec, &mut progress)?;
            (report, vec![path])
        } else if learner.is_vqql() && !config.vqql_sweep.is_empty() {
            let (points, report, paths) =
                vqql_sweep(config, learner, &starts, &spec, &mut progress)?;
            out.vqql_sweep.extend(points);
            (report, paths)
        } else {
            let (report, paths, _) = over_seeds(config, learner, &starts, &spec, &mut progress)?;
            (report, paths)
        };
        out.trajectories.push(paths.remove(0));
        out.seed_trajectories.push(paths);
        out.reports.push(report);
    }
    Ok(out)
}

/// Trains `learner` once on `config` and measures its greedy policy from `x0` and `starts`.
fn measure(
    config: &CompareConfig,
    learner: Learner,
    starts: &[Vec<f64>],
    spec: &RolloutSpec,
    progress: &mut dyn FnMut(Event),
) -> Result<(LearnerReport, Trajectory), SimError> {
    progress(Event::Training(learner));
    let t0 = Instant::now();
    let (policy, mut report) = train_one(config, learner)?;
    report.train_seconds = t0.elapsed().as_secs_f64();
    progress(Event::Trained(
        learner,
        report.iterations,
        report.train_seconds,
    ));
    let Outcome::PointMass {
        trajectory,
        metrics: from_x0,
        ..
    } = evaluate::run(&policy, &config.x0, spec)?
    else {
        unreachable!("a point-mass policy runs on the point masses")
    };
    progress(Event::Evaluating(learner));
    let runs = evaluate::point_mass_starts(&policy, starts, config.steps, PolicyKind::Greedy)?;
    let over = PointMassReport::from_runs(&runs);
    report.final_error_cm = mean_final_error_cm(&from_x0);
    report.time_to_goal_s = from_x0.reach_time_s;
    report.from_x0 = from_x0;
    report.success_rate = over.success_rate;
    report.mean_time_to_goal_s = over.mean_time_to_goal_s;
    report.mean_final_error_cm = over.mean_final_error_cm;
    Ok((report, trajectory))
}

/// Runs the learner from samples `learner` once per seed ([`CompareConfig::seeds`]): the
/// report (the means over seeds when there are several), every seed's path from `x0`, and
/// the measurements over the seeds.
fn over_seeds(
    config: &CompareConfig,
    learner: Learner,
    starts: &[Vec<f64>],
    spec: &RolloutSpec,
    progress: &mut dyn FnMut(Event),
) -> Result<(LearnerReport, Vec<Trajectory>, OverSeeds), SimError> {
    let announce = config.seeds > 1 || (learner.is_vqql() && !config.vqql_sweep.is_empty());
    let (mut runs, mut paths, mut seeds) = (Vec::new(), Vec::new(), Vec::new());
    for k in 0..config.seeds {
        let seed = config.fql.seed.wrapping_add(k as u64);
        if announce {
            progress(Event::Run {
                learner,
                seed,
                cells: learner.is_vqql().then_some(config.vqql.cells),
            });
        }
        let c = if config.seeds > 1 {
            &config.with_seed(seed)
        } else {
            config
        };
        let (report, path) = measure(c, learner, starts, spec, progress)?;
        runs.push(report);
        paths.push(path);
        seeds.push(seed);
    }
    let over = OverSeeds::of(seeds, &runs);
    let mut report = runs[0].clone();
    if runs.len() > 1 {
        let times: Vec<f64> = runs.iter().filter_map(|r| r.mean_time_to_goal_s).collect();
        report.final_error_cm = over.final_error.mean;
        report.time_to_goal_s = over.time_to_goal.map(|e| e.mean);
        report.success_rate = over.success.mean;
        report.mean_final_error_cm = over.mean_final_error.mean;
        report.mean_time_to_goal_s =
            (!times.is_empty()).then(|| times.iter().sum::<f64>() / times.len() as f64);
        report.train_seconds = runs.iter().map(|r| r.train_seconds).sum();
        report.converged = runs.iter().all(|r| r.converged);
        report.largest_parameter = runs
            .iter()
            .filter_map(|r| r.largest_parameter)
            .reduce(f64::max);
        report.notes.insert(
            0,
            format!(
                "{} seeds ({}-{}); notes of the first seed:",
                runs.len(),
                over.seeds[0],
                over.seeds[runs.len() - 1]
            ),
        );
        report.over_seeds = Some(over.clone());
    }
    Ok((report, paths, over))
}

/// VQQL over every codebook size of the sweep: the sweep, and the best size's report and
/// paths (see the [module docs](self#rewards-seeds-and-the-codebook-sweep)).
fn vqql_sweep(
    config: &CompareConfig,
    learner: Learner,
    starts: &[Vec<f64>],
    spec: &RolloutSpec,
    progress: &mut dyn FnMut(Event),
) -> Result<(Vec<SweepPoint>, LearnerReport, Vec<Trajectory>), SimError> {
    let mut points = Vec::new();
    let mut best: Option<(usize, LearnerReport, Vec<Trajectory>)> = None;
    for &cells in &config.vqql_sweep {
        let mut c = config.clone();
        c.vqql.cells = cells;
        let (report, paths, over) = over_seeds(&c, learner, starts, spec, progress)?;
        let better = best.as_ref().is_none_or(|(i, _, _)| {
            let b: &SweepPoint = &points[*i];
            let (s, e) = (over.success.mean, over.mean_final_error.mean);
            let (bs, be) = (
                b.over_seeds.success.mean,
                b.over_seeds.mean_final_error.mean,
            );
            s > bs || (s == bs && e < be)
        });
        if better {
            best = Some((points.len(), report.clone(), paths));
        }
        points.push(SweepPoint {
            learner,
            cells,
            parameters: report.parameters,
            over_seeds: over,
            best: false,
        });
    }
    let (i, mut report, paths) = best.expect("validate: the sweep is not empty");
    points[i].best = true;
    report.notes.insert(
        0,
        format!(
            "the best of the codebook sweep ({} sizes): {} cells per agent",
            points.len(),
            points[i].cells
        ),
    );
    Ok((points, report, paths))
}

/// One point of a sample-efficiency curve ([`sample_efficiency`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct EfficiencyPoint {
    /// The learner.
    pub learner: Learner,
    /// Transitions of interaction with the plant it learned from.
    pub transitions: usize,
    /// Success over the comparison's random starts.
    pub success_rate: f64,
    /// Mean final error over the starts (cm, mean of the agents).
    pub mean_final_error_cm: f64,
    /// Training seconds (collection, fitting and solving, or learning episodes).
    pub train_seconds: f64,
    /// Why the learner produced no policy (too few transitions to estimate its model: a block
    /// action never taken); it then succeeds from no start.
    pub failure: Option<String>,
}

/// `config` with `learner` (if it learns from samples) given `transitions` of interaction with
/// the plant:
/// the learned model collects that many; fuzzy Q-learning runs `transitions / max_steps`
/// learning episodes (at least 1, no greedy evaluations, epsilon decaying over the first 80%);
/// VQQL spends half on the exploration its codebook is built from (its cells capped at half
/// that many states) and half on its learning episodes.
#[must_use]
pub fn with_budget(config: &CompareConfig, learner: Learner, transitions: usize) -> CompareConfig {
    let mut c = config.clone();
    let mut learn_for = |n: usize| {
        c.fql.episodes = (n / c.fql.max_steps.max(1)).max(1);
        c.fql.epsilon_decay_episodes = (c.fql.episodes * 4 / 5).max(1);
        c.fql.eval_every = 0;
    };
    match learner {
        Learner::Fqi | Learner::Crisp | Learner::CrispUniform => {}
        Learner::LearnedModel => c.model_learning.collection.samples = transitions,
        Learner::FqiSamples => c.batch.samples = transitions,
        Learner::VqqlBatch => {
            c.batch.samples = transitions;
            c.vqql.cells = c.vqql.cells.min(c.vqql.samples);
        }
        Learner::Fql | Learner::FqlLiteral => learn_for(transitions),
        Learner::Vqql => {
            learn_for(transitions / 2);
            c.vqql.samples = (transitions / 2).max(1);
            // Repeated states (episodes start at rest) can leave fewer distinct states than
            // samples; half of them always suffice for a codebook.
            c.vqql.cells = c.vqql.cells.min((c.vqql.samples / 2).max(1));
        }
    }
    c
}

/// Success over the random starts against the number of transitions, for every learner of
/// `config` that learns from samples (the learned model, fuzzy Q-learning, VQQL), each budget
/// of `budgets` given as [`with_budget`] says; the model-based learners that use the model
/// itself are left out (they need no transitions). `progress` sees `(learner, budget)` before
/// each training.
pub fn sample_efficiency(
    config: &CompareConfig,
    budgets: &[usize],
    mut progress: impl FnMut(Learner, usize),
) -> Result<Vec<EfficiencyPoint>, SimError> {
    config.validate()?;
    require!(
        !budgets.is_empty(),
        "budgets",
        "name at least one number of transitions"
    );
    require!(
        budgets.iter().all(|&b| b >= 1),
        "budgets",
        "must be at least 1 transition each"
    );
    let model = config.model()?;
    let starts =
        pointmass::random_starts(&model, config.starts, config.seed, config.start_position)?;
    let mut points = Vec::new();
    for &learner in config
        .learners
        .iter()
        .filter(|&&l| l == Learner::LearnedModel || !l.is_model_based())
    {
        for &budget in budgets {
            progress(learner, budget);
            let c = with_budget(config, learner, budget);
            let t0 = Instant::now();
            let policy = match train_one(&c, learner) {
                Ok((policy, _)) => policy,
                // Too few transitions for the estimator: no model, no policy.
                Err(SimError::Config(e)) if learner == Learner::LearnedModel => {
                    points.push(EfficiencyPoint {
                        learner,
                        transitions: budget,
                        success_rate: 0.0,
                        mean_final_error_cm: f64::NAN,
                        train_seconds: t0.elapsed().as_secs_f64(),
                        failure: Some(e.to_string()),
                    });
                    continue;
                }
                Err(e) => return Err(e),
            };
            let train_seconds = t0.elapsed().as_secs_f64();
            let runs =
                evaluate::point_mass_starts(&policy, &starts, config.steps, PolicyKind::Greedy)?;
            let over = PointMassReport::from_runs(&runs);
            points.push(EfficiencyPoint {
                learner,
                transitions: budget,
                success_rate: over.success_rate,
                mean_final_error_cm: over.mean_final_error_cm,
                train_seconds,
                failure: None,
            });
        }
    }
    Ok(points)
}

/// As many cores per state variable as `task`'s grid has, evenly spaced over the variable's
/// range in `model` (ends included): the uniform crisp grid of [`Learner::CrispUniform`].
#[must_use]
pub fn uniform_cores(task: &TrainConfig, model: &PointMass) -> Vec<Vec<f64>> {
    task.grid_cores()
        .iter()
        .enumerate()
        .map(|(d, cores)| {
            let (lo, hi) = fuzzyq_core::Model::<f64>::state_bounds(model, d);
            linspace(lo, hi, cores.len())
        })
        .collect()
}

/// How many cores hold the lowest value. With a positive goal reward (and 0 elsewhere), the
/// cores from which no sequence of the model's transitions reaches a reward all keep one value,
/// the lowest (the same updates from the same start, extrapolation included), and every other
/// core holds more.
fn cores_at_lowest_value(values: &Values) -> u64 {
    fn count<T: PartialOrd + Copy>(v: &[T]) -> u64 {
        let Some(&first) = v.first() else { return 0 };
        let low = v.iter().fold(first, |m, &x| if x < m { x } else { m });
        v.iter().filter(|&&x| x == low).count() as u64
    }
    match values {
        Values::F32(v) => count(v),
        Values::F64(v) => count(v),
    }
}

/// A report with the training fields filled in and the measurements still empty.
fn blank(learner: Learner) -> LearnerReport {
    LearnerReport {
        learner,
        description: learner.description().into(),
        iterations: 0,
        iteration_unit: String::new(),
        converged: false,
        train_seconds: 0.0,
        parameters: 0,
        stored_values: 0,
        from_x0: RolloutMetrics {
            policy_kind: PolicyKind::Greedy,
            x0: Vec::new(),
            steps: 0,
            dt: 0.0,
            reach_step: None,
            reach_time_s: None,
            arrival_time_s: Vec::new(),
            final_error_m: Vec::new(),
            discounted_return: 0.0,
            steps_in_goal: 0,
            value_x0: 0.0,
        },
        final_error_cm: f64::NAN,
        time_to_goal_s: None,
        success_rate: 0.0,
        mean_time_to_goal_s: None,
        mean_final_error_cm: f64::NAN,
        notes: Vec::new(),
        largest_parameter: None,
        over_seeds: None,
    }
}

fn train_one(
    config: &CompareConfig,
    learner: Learner,
) -> Result<(Policy, LearnerReport), SimError> {
    let mut report = blank(learner);
    match learner {
        Learner::Fqi | Learner::Crisp | Learner::CrispUniform => {
            let mut task = config.planning_task();
            task.grid.membership = if learner == Learner::Fqi {
                Membership::Triangular
            } else {
                Membership::Crisp
            };
            if learner == Learner::CrispUniform {
                task.grid.cores = Some(uniform_cores(&task, &config.model()?));
            }
            let artifact: PolicyArtifact =
                train::train(&task, |_| std::ops::ControlFlow::Continue(()))?;
            let n = task.n_cores() as u64;
            report.iterations = artifact.summary.sweeps;
            report.iteration_unit = "sweeps".into();
            report.converged = artifact.summary.converged;
            report.parameters = n * artifact.n_joint_actions() as u64;
            report.stored_values = n;
            let stuck = cores_at_lowest_value(&artifact.values);
            if stuck > 1 && config.model()?.config().goal_reward > 0.0 {
                report.notes.push(format!(
                    "V takes its lowest value at {} of {} cores ({:.1}%): from those the model \
                 never reaches the reward, and every action ties",
                    fmt_count(stuck),
                    fmt_count(n),
                    100.0 * stuck as f64 / n as f64
                ));
            }
            Ok((Policy::Fqi(FqiPolicy::from_artifact(artifact)?), report))
        }
        Learner::LearnedModel => {
            let mut task = config.planning_task();
            task.grid.membership = Membership::Triangular;
            let run = train::train_learned(&task, &config.model_learning, |_| {
                std::ops::ControlFlow::Continue(())
            })?;
            let artifact = run.artifact;
            let n = task.n_cores() as u64;
            report.iterations = artifact.summary.sweeps;
            report.iteration_unit = "sweeps".into();
            report.converged = artifact.summary.converged;
            report.parameters = n * artifact.n_joint_actions() as u64;
            let entries: usize = artifact
                .learned
                .as_ref()
                .map_or(0, |t| t.blocks.iter().map(|b| b.weight.len()).sum());
            report.stored_values = n + entries as u64;
            let c = &config.model_learning.collection;
            let worst = run.table_error.iter().fold(0.0f64, |m, e| m.max(e.max_l1));
            report.notes.push(format!(
                "model learned from {} transitions (random actions, episodes of {} steps, seed \
                 {}); {} of its rows needed a wider kernel; largest L1 distance of a row to the \
                 true noise-free model's {worst:.2e}",
                c.samples,
                c.episode_steps,
                c.seed,
                run.fit.under_sampled_rows()
            ));
            Ok((Policy::Fqi(FqiPolicy::from_artifact(artifact)?), report))
        }
        Learner::FqiSamples | Learner::VqqlBatch => fitted_from_samples(config, learner, report),
        Learner::Fql | Learner::FqlLiteral | Learner::Vqql => {
            let mut fql = config.fql.clone();
            fql.gamma = config.task.solver.gamma;
            fql.update = if learner == Learner::FqlLiteral {
                Update::Literal
            } else {
                Update::Corrected
            };
            let vqql = learner == Learner::Vqql;
            let learning = SampleLearning {
                learner: if vqql {
                    train::Learner::Vqql
                } else {
                    train::Learner::Fql
                },
                fql,
                starts: config.fql_starts.clone(),
                vqql: vqql.then(|| config.vqql.clone()),
            };
            let learned = train::learn_from_samples(
                &config.task,
                &learning,
                |_: &crate::learn::fql::EpisodeRecord| std::ops::ControlFlow::Continue(()),
            )?;
            let outcome = &learned.outcome;
            if let Some(lloyd) = &learned.lloyd {
                report.record_codebook(config.vqql.cells, lloyd);
            }
            report.iterations = outcome.curve.len();
            report.iteration_unit = "episodes".into();
            report.converged = outcome.converged_at.is_some();
            let largest = report.record_parameters(&outcome.q);
            // Under the paper's reward a positive return means the goal was met; a shaped
            // return says nothing of it.
            if config.reward() == RewardShape::Paper {
                let rewarded = outcome.curve.iter().filter(|r| r.ret > 0.0).count();
                report.notes.push(format!(
                    "{rewarded} of {} learning episodes met the reward",
                    outcome.curve.len()
                ));
            }
            report
                .notes
                .push(format!("largest |parameter| {largest:.3e}"));
            Ok((Policy::from_file(learned.file)?, report))
        }
    }
}

/// [`Learner::FqiSamples`] and [`Learner::VqqlBatch`]: fitted Q-iteration on the
/// [`CompareConfig::batch`] transitions (the task's reward), over the task's own-state cores
/// or over VQQL's codebook (built as [`Learner::Vqql`] builds it).
fn fitted_from_samples(
    config: &CompareConfig,
    learner: Learner,
    mut report: LearnerReport,
) -> Result<(Policy, LearnerReport), SimError> {
    let model = config.model()?;
    let c = &config.batch;
    let data = train::collect_from_plant(
        &EnvModel::PointMass(model.clone()),
        c,
        &mut Exploration::Random,
    )?;
    let features = if learner == Learner::VqqlBatch {
        let (features, lloyd) = vqql::build_codebook(&model, &config.fql_starts, &config.vqql)?;
        report.record_codebook(config.vqql.cells, &lloyd);
        features
    } else {
        let g = &config.task.grid;
        pointmass_task::feature_space(&model, &g.position_cores, &g.velocity_cores)?
    };
    let s = &config.task.solver;
    let out = fitted::fitted_q(
        &data,
        &features,
        F64Model::actions(&model),
        &FittedConfig {
            gamma: s.gamma,
            xi: s.xi,
            max_iterations: s.max_sweeps,
        },
    )?;
    report.iterations = out.iterations;
    report.iteration_unit = "iterations".into();
    report.converged = out.converged;
    let largest = report.record_parameters(&out.q);
    report.notes.push(format!(
        "fitted on {} transitions (random actions, episodes of {} steps, seed {}); largest \
         |parameter| {largest:.3e}",
        c.samples, c.episode_steps, c.seed
    ));
    let policy = AdditivePolicy::point_masses(model, out.q, s.gamma)?;
    Ok((Policy::Additive(policy), report))
}

fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "never".into(), |v| format!("{v:.digits$}"))
}

/// `mean [lo, hi]`, each times `scale`, with `digits` decimals.
fn fmt_estimate(e: &Estimate, digits: usize, scale: f64) -> String {
    format!(
        "{:.digits$} [{:.digits$}, {:.digits$}]",
        e.mean * scale,
        e.lo * scale,
        e.hi * scale
    )
}

fn fmt_count(n: u64) -> String {
    let s = n.to_string();
    let mut out = String::new();
    for (i, c) in s.chars().enumerate() {
        if i > 0 && (s.len() - i).is_multiple_of(3) {
            out.push(',');
        }
        out.push(c);
    }
    out
}

impl Comparison {
    /// The table as Markdown: one column per learner, then the paper's two columns.
    #[must_use]
    pub fn to_markdown(&self) -> String {
        let mut rows: Vec<(String, Vec<String>, [String; 2])> = Vec::new();
        let paper = |i: usize| {
            let (_, c, f) = paper::TABLE1[i];
            [format!("{c}"), format!("{f}")]
        };
        let none = || [String::from("-"), String::from("-")];
        let col = |f: &dyn Fn(&LearnerReport) -> String| self.reports.iter().map(f).collect();
        // A mean with its interval where the learner ran over seeds.
        let est = |r: &LearnerReport, plain: String, pick: &dyn Fn(&OverSeeds) -> String| {
            r.over_seeds.as_ref().map_or(plain, pick)
        };
        rows.push((
            "final error from x0 (cm)".into(),
            col(&|r| {
                est(r, format!("{:.1}", r.final_error_cm), &|o| {
                    fmt_estimate(&o.final_error, 1, 1.0)
                })
            }),
            paper(0),
        ));
        rows.push((
            "time to goal from x0 (s)".into(),
            col(&|r| {
                est(r, fmt_opt(r.time_to_goal_s, 1), &|o| {
                    let reached = o.time_to_goal_s.iter().flatten().count();
                    o.time_to_goal.map_or_else(
                        || "never".into(),
                        |e| {
                            format!(
                                "{} ({reached} of {} seeds)",
                                fmt_estimate(&e, 1, 1.0),
                                o.seeds.len()
                            )
                        },
                    )
                })
            }),
            paper(1),
        ));
        rows.push((
            "iterations".into(),
            col(&|r| {
                let unit = match r.iterations {
                    1 => r.iteration_unit.trim_end_matches('s'),
                    _ => &r.iteration_unit,
                };
                format!(
                    "{} {unit}{}",
                    r.iterations,
                    if r.converged { "" } else { " (not converged)" }
                )
            }),
            paper(2),
        ));
        rows.push((
            "training (s)".into(),
            col(&|r| format!("{:.1}", r.train_seconds)),
            none(),
        ));
        rows.push((
            "parameters".into(),
            col(&|r| fmt_count(r.parameters)),
            none(),
        ));
        rows.push((
            "largest parameter".into(),
            col(&|r| {
                r.largest_parameter
                    .map_or("-".into(), |p| format!("{p:.3e}"))
            }),
            none(),
        ));
        rows.push((
            format!("success over {} starts", self.starts),
            col(&|r| {
                est(r, format!("{:.0}%", 100.0 * r.success_rate), &|o| {
                    format!("{}%", fmt_estimate(&o.success, 0, 100.0))
                })
            }),
            none(),
        ));
        rows.push((
            "mean time to goal (s)".into(),
            col(&|r| fmt_opt(r.mean_time_to_goal_s, 1)),
            none(),
        ));
        rows.push((
            "mean final error (cm)".into(),
            col(&|r| {
                est(r, format!("{:.1}", r.mean_final_error_cm), &|o| {
                    fmt_estimate(&o.mean_final_error, 1, 1.0)
                })
            }),
            none(),
        ));
        let mut out = String::from("| |");
        for r in &self.reports {
            out.push_str(&format!(" {} |", r.learner.name()));
        }
        out.push_str(" paper: CMOMMT | paper: fuzzy |\n|---|");
        out.push_str(&"---|".repeat(self.reports.len() + 2));
        out.push('\n');
        for (name, cells, paper) in rows {
            out.push_str(&format!("| {name} |"));
            for c in cells {
                out.push_str(&format!(" {c} |"));
            }
            out.push_str(&format!(" {} | {} |\n", paper[0], paper[1]));
        }
        out.push_str(&format!(
            "\nReward: {}. x0 = {:?}; {} steps of {} s; {} random starts at rest within {} m \
             (seed {}); goal: the reward region ||x||_2 < 0.1 over the whole state. Over \
             several seeds: mean [95% bootstrap interval].\n",
            self.reward_description(),
            self.x0,
            self.steps,
            self.dt,
            self.starts,
            self.start_position,
            self.seed
        ));
        for r in &self.reports {
            for n in &r.notes {
                out.push_str(&format!("- {}: {n}\n", r.learner.name()));
            }
        }
        if !self.vqql_sweep.is_empty() {
            out.push_str(&self.sweep_markdown());
        }
        out
    }

    fn reward_description(&self) -> &'static str {
        match self.reward {
            RewardShape::Paper => "the paper's (goal reward only)",
            RewardShape::Shaped => {
                "shaped, the paper's plus gamma Phi(x') - Phi(x) with Phi(x) = -sum_i ||x_i|| \
                 (the learners from samples; the learners that plan with the model plan with \
                 the paper's reward, the same greedy policy)"
            }
        }
    }

    /// The VQQL codebook sweep as a Markdown table.
    fn sweep_markdown(&self) -> String {
        let mut out = String::from(
            "\nVQQL codebook sweep (mean [95% bootstrap interval] over seeds; * the best: the \
             highest success over the random starts, then the lowest mean final error):\n\n\
             | learner | cells per agent | parameters | final error from x0 (cm) | success over \
             starts | mean final error (cm) |\n|---|---|---|---|---|---|\n",
        );
        for p in &self.vqql_sweep {
            let o = &p.over_seeds;
            out.push_str(&format!(
                "| {} | {}{} | {} | {} | {}% | {} |\n",
                p.learner.name(),
                p.cells,
                if p.best { " *" } else { "" },
                fmt_count(p.parameters),
                fmt_estimate(&o.final_error, 1, 1.0),
                fmt_estimate(&o.success, 0, 100.0),
                fmt_estimate(&o.mean_final_error, 1, 1.0),
            ));
        }
        out
    }

    /// The table as CSV: one row per learner.
    #[must_use]
    pub fn to_csv(&self) -> String {
        let mut out = String::from(
            "learner,final_error_cm,time_to_goal_s,iterations,iteration_unit,converged,\
             train_seconds,parameters,stored_values,success_rate,mean_time_to_goal_s,\
             mean_final_error_cm,largest_parameter,seeds,final_error_lo,final_error_hi,\
             success_lo,success_hi,mean_final_error_lo,mean_final_error_hi\n",
        );
        let opt = |v: Option<f64>| v.map_or_else(String::new, |v| v.to_string());
        for r in &self.reports {
            let o = r.over_seeds.as_ref();
            let ci = |f: &dyn Fn(&OverSeeds) -> Estimate| {
                o.map_or_else(|| ",".to_string(), |o| format!("{},{}", f(o).lo, f(o).hi))
            };
            out.push_str(&format!(
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
                r.learner.name(),
                r.final_error_cm,
                opt(r.time_to_goal_s),
                r.iterations,
                r.iteration_unit,
                r.converged,
                r.train_seconds,
                r.parameters,
                r.stored_values,
                r.success_rate,
                opt(r.mean_time_to_goal_s),
                r.mean_final_error_cm,
                opt(r.largest_parameter),
                o.map_or(1, |o| o.seeds.len()),
                ci(&|o| o.final_error),
                ci(&|o| o.success),
                ci(&|o| o.mean_final_error),
            ));
        }
        out
    }
}

#[cfg(test)]
mod tests;
