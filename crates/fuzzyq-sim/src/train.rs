//! Training: a configuration in, a policy file's content out, for every learner.
//!
//! - [`train`]: joint fuzzy Q-iteration on the model (the paper's method), either operator;
//! - [`train_learned`]: the same on a fuzzy model learned from transitions collected on the
//!   plant ([`crate::learn::samples`], [`crate::learn::fit`]), the model never consulted;
//! - [`learn_from_samples`]: fuzzy Q-learning (the additive layout, corrected or printed
//!   update) on the point masses or the robots, and VQQL on the point masses, with the
//!   defaults of [`SampleLearning::defaults`].

use std::ops::ControlFlow;

use fuzzyq_core::Real;
use fuzzyq_core::q::PolicyKind;
use fuzzyq_core::solver::{
    self, Delta, Device, IterationOperator, Precision, Progress, Scheme, Solution, SolveError,
    SolverState, SweepRecord,
};
use serde::Serialize;

use crate::error::{ConfigError, SimError};
use crate::io::checkpoint::FqiState;
use crate::io::config::{EnvConfig, TrainConfig};
use crate::io::policy_file::{
    KheperaPolicyFile, PointMassPolicyFile, PolicyArtifact, PolicyFile, TrainSummary, Values,
};
use crate::learn::fit::{self, FitConfig, FitReport, TableError};
use crate::learn::fql::{FqlConfig, FqlOutcome};
use crate::learn::samples::{self, Collection, Exploration, Transitions};
use crate::learn::tasks::{khepera as khepera_task, pointmass as pointmass_task};
use crate::learn::vqql::{self, LloydReport, VqqlConfig};
use crate::model::learned::LearnedModel;
use crate::model::pointmass::{PointMass, Starts};
use crate::model::{BlockSpec, Dynamics, EnvModel, F64Model};
use crate::run::policy::{FqiPolicy, Scratch};

fuzzyq_core::named_option! {
    /// What learns a policy.
    #[derive(Default)]
    pub enum Learner: "learner" {
        /// Joint fuzzy Q-iteration on the model.
        #[default]
        Fqi = "fqi" => "joint fuzzy Q-iteration on the model",
        /// Model-free fuzzy Q-learning, additive layout.
        Fql = "fql" => "model-free fuzzy Q-learning (additive layout)",
        /// VQQL: k-means cells per agent and tabular Q-learning (point masses).
        Vqql = "vqql" => "VQQL: k-means cells and tabular Q-learning (point masses)",
        /// Joint fuzzy Q-iteration on a fuzzy model learned from transitions.
        LearnedModel = "learned-model" => "fuzzy Q-iteration on a model learned from transitions",
    }
}

/// Checks a worker-thread count for a run on this machine: at least 1, and at most 8 per
/// core (at least 64); more workers only add memory (a stack each) and contention, and a huge
/// count would exhaust the memory starting them. The error says what was expected (the
/// command line prefixes `--threads`, Python `threads`).
pub fn check_threads(n: usize) -> Result<(), String> {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    let most = (8 * cores).max(64);
    if (1..=most).contains(&n) {
        Ok(())
    } else {
        Err(format!(
            "expected 1 to {most} on this machine ({cores} cores), got {n}"
        ))
    }
}

/// Runs fuzzy Q-iteration as configured; `observer` sees every sweep and may stop the run
/// ([`SolveError::Interrupted`]).
pub fn train(
    config: &TrainConfig,
    mut observer: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<PolicyArtifact, SimError> {
    train_from(config, None, |p, _| observer(p))
}

/// [`train`], continued from the state of an earlier run of the same configuration
/// (`resume`) or started afresh; the observer also sees the run's state after every sweep
/// that does not end it (to [checkpoint](crate::io::checkpoint) it). A continued run gives
/// the policy of the uninterrupted one, bit for bit. Continuing needs the values operator:
/// Busoniu's (`solver.operator = "q-values"`) is refused with a state.
pub fn train_from(
    config: &TrainConfig,
    resume: Option<FqiState<'static>>,
    observer: impl FnMut(&Progress, Option<&FqiState<'_>>) -> ControlFlow<()>,
) -> Result<PolicyArtifact, SimError> {
    train_showing(config, resume, true, observer)
}

/// [`train_from`], the observer shown the run's state only with `show_state`: on the GPU
/// (`solver.device = "gpu"`) a state is read back from the device after every sweep, so a
/// caller that keeps none (no checkpoints) runs faster without. On the CPU the state costs
/// nothing and is always shown.
pub fn train_showing(
    config: &TrainConfig,
    resume: Option<FqiState<'static>>,
    show_state: bool,
    observer: impl FnMut(&Progress, Option<&FqiState<'_>>) -> ControlFlow<()>,
) -> Result<PolicyArtifact, SimError> {
    config.validate()?;
    let model = config.build_model()?;
    solve_and_pack(&model, config, resume, show_state, observer)
}

/// [`train_from`] with the passes over `V` run by `sweeps`, a backend that holds `V`
/// elsewhere (in shards on a cluster, say) and computes every pass from the slab entry
/// points ([`crate::slabs::SlabProblem`]): the same policy, bit for bit, as [`train_from`]
/// when the backend computes each pass as the in-process one does.
///
/// The observer is shown the run's state (every value, read from the backend) only with
/// `show_state`. Fuzzy Q-iteration's values operator with synchronous sweeps only: the
/// q-values operator and asynchronous sweeps are refused (neither runs on slabs).
pub fn train_on<S, E>(
    config: &TrainConfig,
    sweeps: &mut S,
    resume: Option<FqiState<'static>>,
    show_state: bool,
    mut observer: impl FnMut(&Progress, Option<&FqiState<'_>>) -> ControlFlow<()>,
) -> Result<PolicyArtifact, E>
where
    S: solver::Sweeps<f32, Error = E> + solver::Sweeps<f64, Error = E>,
    E: From<SimError> + From<SolveError>,
{
    crate::slabs::check_shardable(config).map_err(SimError::from)?;
    let model = config.build_model()?;
    match split_resume(config, resume)? {
        Resume::F32(resume) => {
            solve_on_t(&model, config, sweeps, resume, show_state, &mut observer)
        }
        Resume::F64(resume) => {
            solve_on_t(&model, config, sweeps, resume, show_state, &mut observer)
        }
    }
}

/// [`train_on`] in the precision `T`.
fn solve_on_t<T, S, E>(
    model: &EnvModel,
    config: &TrainConfig,
    sweeps: &mut S,
    resume: Option<SolverState<'static, T>>,
    show_state: bool,
    observer: &mut impl FnMut(&Progress, Option<&FqiState<'_>>) -> ControlFlow<()>,
) -> Result<PolicyArtifact, E>
where
    T: Stored,
    EnvModel: fuzzyq_core::Model<T>,
    S: solver::Sweeps<T, Error = E>,
    E: From<SimError> + From<SolveError>,
{
    let grid = config.grid::<T>()?;
    let s = solver::solve_on(
        model,
        &grid,
        &config.solver.solver_config(),
        sweeps,
        resume,
        show_state,
        |p, s| observer(p, s.map(T::state).as_ref()),
    )?;
    Ok(artifact(config, s, T::values))
}

/// A solver precision as checkpoints and policy files hold it.
trait Stored: DeviceReal {
    /// A run's state as a checkpoint holds it.
    fn state<'a>(s: &SolverState<'a, Self>) -> FqiState<'a>;
    /// Values as a policy file holds them.
    fn values(v: Vec<Self>) -> Values;
}

impl Stored for f32 {
    fn state<'a>(s: &SolverState<'a, f32>) -> FqiState<'a> {
        FqiState::F32(s.clone())
    }
    fn values(v: Vec<f32>) -> Values {
        Values::F32(v)
    }
}

impl Stored for f64 {
    fn state<'a>(s: &SolverState<'a, f64>) -> FqiState<'a> {
        FqiState::F64(s.clone())
    }
    fn values(v: Vec<f64>) -> Values {
        Values::F64(v)
    }
}

/// A floating-point type a run can take to a [`Device`]: `f32` runs on the GPU too, `f64`
/// only on the CPU.
pub trait DeviceReal: Real {
    /// [`solver::solve_from`] of `model` on `device` (`show_state`: whether the observer is
    /// shown the run's state, which the GPU reads back after every sweep).
    fn solve_on_device<M: fuzzyq_core::Model<Self> + Sync + ?Sized>(
        device: Device,
        model: &M,
        grid: &solver::Grid<Self>,
        config: &solver::SolverConfig,
        resume: Option<SolverState<'_, Self>>,
        show_state: bool,
        observer: impl FnMut(&Progress, Option<&SolverState<'_, Self>>) -> ControlFlow<()>,
    ) -> Result<Solution<Self>, SimError>;
}

impl DeviceReal for f32 {
    fn solve_on_device<M: fuzzyq_core::Model<f32> + Sync + ?Sized>(
        device: Device,
        model: &M,
        grid: &solver::Grid<f32>,
        config: &solver::SolverConfig,
        resume: Option<SolverState<'_, f32>>,
        show_state: bool,
        observer: impl FnMut(&Progress, Option<&SolverState<'_, f32>>) -> ControlFlow<()>,
    ) -> Result<Solution<f32>, SimError> {
        match device {
            Device::Cpu => Ok(solver::solve_from(model, grid, config, resume, observer)?),
            // The GPU waited for once the operator is prepared: an open the command line began
            // in the background overlaps that preparation.
            Device::Gpu => Ok(fuzzyq_gpu::solve_shared(
                model, grid, config, resume, show_state, observer,
            )?),
        }
    }
}

impl DeviceReal for f64 {
    fn solve_on_device<M: fuzzyq_core::Model<f64> + Sync + ?Sized>(
        device: Device,
        model: &M,
        grid: &solver::Grid<f64>,
        config: &solver::SolverConfig,
        resume: Option<SolverState<'_, f64>>,
        _show_state: bool,
        observer: impl FnMut(&Progress, Option<&SolverState<'_, f64>>) -> ControlFlow<()>,
    ) -> Result<Solution<f64>, SimError> {
        match device {
            Device::Cpu => Ok(solver::solve_from(model, grid, config, resume, observer)?),
            Device::Gpu => Err(ConfigError::invalid(
                "solver.device",
                "\"gpu\" runs in f32; set solver.precision = \"f32\"",
            )
            .into()),
        }
    }
}

/// A run's state to continue from, in the configured precision.
enum Resume {
    F32(Option<SolverState<'static, f32>>),
    F64(Option<SolverState<'static, f64>>),
}

/// `resume` in `config`'s precision, or the error naming the mismatch.
fn split_resume(
    config: &TrainConfig,
    resume: Option<FqiState<'static>>,
) -> Result<Resume, SimError> {
    match (config.solver.precision, resume) {
        (Precision::F32, None) => Ok(Resume::F32(None)),
        (Precision::F64, None) => Ok(Resume::F64(None)),
        (Precision::F32, Some(FqiState::F32(s))) => Ok(Resume::F32(Some(s))),
        (Precision::F64, Some(FqiState::F64(s))) => Ok(Resume::F64(Some(s))),
        _ => Err(ConfigError::invalid(
            "checkpoint",
            format!(
                "holds values in the other precision than solver.precision = \"{}\"",
                config.solver.precision.name()
            ),
        )
        .into()),
    }
}

/// Solves `model` with the grid and solver settings of `config` in its precision, from
/// `resume` if given.
fn solve_and_pack<M>(
    model: &M,
    config: &TrainConfig,
    resume: Option<FqiState<'static>>,
    show_state: bool,
    observer: impl FnMut(&Progress, Option<&FqiState<'_>>) -> ControlFlow<()>,
) -> Result<PolicyArtifact, SimError>
where
    M: fuzzyq_core::Model<f32> + fuzzyq_core::Model<f64> + Sync,
{
    match split_resume(config, resume)? {
        Resume::F32(resume) => solve_and_pack_t(model, config, resume, show_state, observer),
        Resume::F64(resume) => solve_and_pack_t(model, config, resume, show_state, observer),
    }
}

/// [`solve_and_pack`] in the precision `T`: on the configured device (the GPU runs `f32`
/// only), the values operator or the q-values one.
fn solve_and_pack_t<T: Stored, M: fuzzyq_core::Model<T> + Sync>(
    model: &M,
    config: &TrainConfig,
    resume: Option<SolverState<'static, T>>,
    show_state: bool,
    mut observer: impl FnMut(&Progress, Option<&FqiState<'_>>) -> ControlFlow<()>,
) -> Result<PolicyArtifact, SimError> {
    let s = if config.solver.device == Device::Gpu {
        let grid = config.grid::<T>()?;
        T::solve_on_device(
            Device::Gpu,
            model,
            &grid,
            &config.solver.solver_config(),
            resume,
            show_state,
            |p, s| observer(p, s.map(T::state).as_ref()),
        )?
    } else {
        solve::<T, M>(model, config, resume, |p, s| {
            observer(p, s.map(T::state).as_ref())
        })?
    };
    Ok(artifact(config, s, T::values))
}

fn solve<T: Real, M: fuzzyq_core::Model<T> + Sync>(
    model: &M,
    config: &TrainConfig,
    resume: Option<SolverState<'static, T>>,
    mut observer: impl FnMut(&Progress, Option<&SolverState<'_, T>>) -> ControlFlow<()>,
) -> Result<Solution<T>, SimError> {
    let grid = config.grid::<T>()?;
    let solver_config = config.solver.solver_config();
    if config.solver.operator == IterationOperator::Values {
        return Ok(solver::solve_from(
            model,
            &grid,
            &solver_config,
            resume,
            observer,
        )?);
    }
    if resume.is_some() {
        return Err(ConfigError::invalid(
            "checkpoint",
            "runs of solver.operator = \"q-values\" cannot be continued (use \"values\")",
        )
        .into());
    }
    // Busoniu's operator: theta stored; reported in the solver's terms (exact deltas).
    let start = std::time::Instant::now();
    let mut records: Vec<SweepRecord> = Vec::new();
    let mut bound = 0;
    let q = solver::solve_q(model, &grid, &solver_config, |k, delta| {
        if k == 1 {
            // theta_1 = rho, so the first change is max |rho|.
            bound = solver_config.sweep_bound(delta);
        }
        let record = SweepRecord {
            sweep: k,
            delta: Delta {
                lower: delta,
                upper: delta,
            },
            delta_v: f64::NAN,
            seconds: start.elapsed().as_secs_f64(),
            extrapolated: false,
            evaluation: false,
        };
        records.push(record);
        observer(
            &Progress {
                record,
                bound,
                xi: solver_config.xi,
                scheme: Scheme::Value,
                extrapolate: false,
                coarse: None,
            },
            None,
        )
    })?;
    for (r, &dv) in records.iter_mut().zip(&q.v_deltas) {
        r.delta_v = dv;
    }
    Ok(Solution {
        v: q.v,
        greedy: q.greedy,
        final_delta: q.deltas.last().copied().unwrap_or(f64::NAN),
        reward_bound: q.deltas.first().copied().unwrap_or(0.0),
        sweeps: records,
        scheme: solver::Scheme::Value,
        stop: q.stop,
        bound,
        path: solver::BackupPath::Generic,
        kernel: "q-values",
        multiply_adds_per_sweep: None,
        sweep_seconds: q.seconds,
        evaluation_seconds: 0.0,
        seconds: start.elapsed().as_secs_f64(),
        // Busoniu's operator reports its sweeps only.
        setup_seconds: None,
        result_seconds: None,
        coarse: None,
    })
}

fn artifact<T>(
    config: &TrainConfig,
    s: Solution<T>,
    values: impl FnOnce(Vec<T>) -> Values,
) -> PolicyArtifact {
    PolicyArtifact {
        config: config.clone(),
        summary: TrainSummary::from_solution(&s),
        values: values(s.v),
        greedy: s.greedy,
        learned: None,
    }
}

/// How the learned-model learner gathers its data and fits its model.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ModelLearning {
    /// The interaction with the plant (each round's).
    pub collection: Collection,
    /// The estimator's settings.
    pub fit: FitConfig,
    /// Rounds of collection, `>= 1`: the first with random actions; each further one collects
    /// `collection.samples` more transitions epsilon-greedily with the policy solved on the
    /// model fitted so far, then refits on all of them and solves again.
    pub rounds: usize,
    /// The further rounds' probability of a random action, per agent and step, in `[0, 1]`.
    pub epsilon: f64,
}

impl ModelLearning {
    /// `samples` transitions in episodes of 50 steps from `seed`, the default fit, one round
    /// (epsilon 0.1 if more rounds are set).
    #[must_use]
    pub fn new(samples: usize, seed: u64) -> Self {
        Self {
            collection: Collection {
                samples,
                episode_steps: 50,
                seed,
            },
            fit: FitConfig::default(),
            rounds: 1,
            epsilon: 0.1,
        }
    }

    /// Checks the settings; errors name the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.collection.validate()?;
        crate::error::require!(self.rounds >= 1, "rounds", "must be at least 1");
        crate::error::require!(
            (0.0..=1.0).contains(&self.epsilon),
            "epsilon",
            format!("must be in [0, 1], got {}", self.epsilon)
        );
        Ok(())
    }

    /// The seed of round `round`'s collection (round 0's is the configured one).
    #[must_use]
    pub fn round_seed(&self, round: usize) -> u64 {
        self.collection.seed ^ (round as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
    }
}

/// One round of [`train_learned`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Round {
    /// Transitions fitted in this round (all rounds' so far).
    pub transitions: usize,
    /// Rows of this round's fit that needed a wider kernel than their core's.
    pub under_sampled_rows: usize,
    /// Sweeps of this round's solve.
    pub sweeps: usize,
    /// Seconds of the round: collection, fit and solve.
    pub seconds: f64,
}

impl Round {
    fn new(
        data: &Transitions,
        fit: &FitReport,
        artifact: &PolicyArtifact,
        start: std::time::Instant,
    ) -> Self {
        Self {
            transitions: data.len(),
            under_sampled_rows: fit.under_sampled_rows(),
            sweeps: artifact.summary.sweeps,
            seconds: start.elapsed().as_secs_f64(),
        }
    }
}

/// What [`train_learned`] produced.
#[derive(Clone, Debug)]
pub struct LearnedModelRun {
    /// The policy file's content (it carries the learned tables).
    pub artifact: PolicyArtifact,
    /// How the estimation went.
    pub fit: FitReport,
    /// The estimated rows' distance to the true noise-free model's (a check the built-in
    /// environments allow; the learner never used the model).
    pub table_error: Vec<TableError>,
    /// Seconds spent collecting and fitting, over every round (the last solve's are in the
    /// artifact's summary).
    pub learning_seconds: f64,
    /// Every round, in order (one unless [`ModelLearning::rounds`] asks for more).
    pub rounds: Vec<Round>,
}

/// Where the episodes of the learned-model learner start: the point masses' random starts
/// at rest over the whole field (those of [`pointmass_task::default_starts`]), the classic
/// benchmarks' uniformly over their state ranges.
fn draw_start(model: &EnvModel) -> impl FnMut(&mut rand_pcg::Pcg64Mcg, &mut [f64]) + '_ {
    use rand::Rng;
    let starts = pointmass_task::default_starts();
    move |rng, x| match model {
        EnvModel::PointMass(_) => starts.draw(rng, x),
        other => {
            for (d, v) in x.iter_mut().enumerate() {
                let (lo, hi) = Dynamics::state_bounds(other, d);
                *v = rng.random_range(lo..=hi);
            }
        }
    }
}

/// Transitions of `task`'s plant as the learned-model learner collects them: seeded episodes
/// from the task's starts, the agents acting as `exploration` says ([`samples::collect`]),
/// with its process noise; for the Khepera robots, on the rapier plant with its wheel noise
/// ([`samples::collect_khepera`]).
pub fn collect_from_plant(
    task: &EnvModel,
    collection: &Collection,
    exploration: &mut Exploration<'_>,
) -> Result<Transitions, SimError> {
    match task {
        EnvModel::Khepera(robots) => samples::collect_khepera(robots, collection, exploration),
        _ => samples::collect(task, collection, draw_start(task), exploration),
    }
}

/// Fuzzy Q-iteration on a model learned from interaction: collects
/// `learning.collection.samples` transitions on the plant of `config`'s environment (with its
/// process noise), estimates the block tables on the configured grid ([`fit::fit`]; the
/// blocks are the environment's declared ones, or one block of the whole state), and solves
/// the learned model as [`train`] solves the true one. Every built-in environment without
/// terminal states is supported (the Khepera robots learn on their rapier plant).
///
/// With [`ModelLearning::rounds`] above 1, each further round collects as many transitions
/// again, epsilon-greedily with the policy of the previous round (seeded with
/// [`ModelLearning::round_seed`]), refits on everything collected so far and solves again;
/// the run reports the last round's fit and policy.
pub fn train_learned(
    config: &TrainConfig,
    learning: &ModelLearning,
    mut observer: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<LearnedModelRun, SimError> {
    config.validate()?;
    learning.validate()?;
    check_learnable(config)?;
    let task = config.build_model()?;
    let mut rounds: Vec<Round> = Vec::with_capacity(learning.rounds);
    let mut learning_seconds = 0.0;
    let mut start = std::time::Instant::now();
    let mut data = collect_from_plant(&task, &learning.collection, &mut Exploration::Random)?;
    loop {
        let (artifact, fit, table_error, seconds) =
            fit_and_solve(config, &task, &data, &learning.fit, start, &mut observer)?;
        learning_seconds += seconds;
        rounds.push(Round::new(&data, &fit, &artifact, start));
        if rounds.len() >= learning.rounds {
            return Ok(LearnedModelRun {
                artifact,
                fit,
                table_error,
                learning_seconds,
                rounds,
            });
        }
        start = std::time::Instant::now();
        let collection = Collection {
            seed: learning.round_seed(rounds.len()),
            ..learning.collection
        };
        let policy = FqiPolicy::from_artifact(artifact)?;
        let mut q = vec![0.0; policy.n_joint_actions()];
        let mut u = vec![0.0; policy.action_dim()];
        let mut scratch = Scratch::default();
        let mut greedy = |x: &[f64], out: &mut [usize]| {
            let joint = policy
                .act_with(PolicyKind::Greedy, x, &mut q, &mut u, &mut scratch)?
                .unwrap_or_default();
            policy.agent_indices(joint, out)
        };
        let mut exploration = Exploration::EpsilonGreedy {
            epsilon: learning.epsilon,
            greedy: &mut greedy,
        };
        data.append(&collect_from_plant(&task, &collection, &mut exploration)?)?;
    }
}

/// Whether the learned-model learner can learn the environment of `config`: every built-in
/// environment without terminal states; the error says why not.
pub fn check_learnable(config: &TrainConfig) -> Result<(), SimError> {
    let task = config.build_model()?;
    if Dynamics::has_terminal_states(&task) {
        return Err(ConfigError::invalid(
            "learner",
            format!(
                "learned-model cannot learn {}: its episodes end in terminal states, which \
                 block tables cannot represent",
                task.name()
            ),
        )
        .into());
    }
    Ok(())
}

/// Fits `data` on the grid of `config` and solves the learned model.
fn fit_and_solve(
    config: &TrainConfig,
    task: &EnvModel,
    data: &Transitions,
    fit_config: &FitConfig,
    start: std::time::Instant,
    mut observer: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<(PolicyArtifact, FitReport, Vec<TableError>, f64), SimError> {
    let declared = F64Model::blocks(task);
    let whole = [BlockSpec {
        state_dims: (0..F64Model::state_dim(task)).collect(),
        action_components: (0..F64Model::actions(task).dim() * F64Model::n_agents(task)).collect(),
    }];
    let blocks = if declared.is_empty() {
        &whole[..]
    } else {
        declared
    };
    let fit_config = FitConfig {
        membership: config.grid.membership,
        ..*fit_config
    };
    let (tables, report) = fit::fit(task, &config.grid_cores(), blocks, data, &fit_config)?;
    let table_error = fit::table_error(&tables, task)?;
    let learned = LearnedModel::new(task.clone(), tables.clone())?;
    let learning_seconds = start.elapsed().as_secs_f64();
    let mut artifact = solve_and_pack(&learned, config, None, false, |p, _| observer(p))?;
    artifact.learned = Some(Box::new(tables));
    Ok((artifact, report, table_error, learning_seconds))
}

/// [`train_learned`] on given transitions (a user's logged data) instead of collecting them.
pub fn train_on_transitions(
    config: &TrainConfig,
    data: &Transitions,
    fit_config: &FitConfig,
    observer: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<LearnedModelRun, SimError> {
    config.validate()?;
    check_learnable(config)?;
    let start = std::time::Instant::now();
    let task = config.build_model()?;
    let (artifact, fit, table_error, learning_seconds) =
        fit_and_solve(config, &task, data, fit_config, start, observer)?;
    let rounds = vec![Round::new(data, &fit, &artifact, start)];
    Ok(LearnedModelRun {
        artifact,
        fit,
        table_error,
        learning_seconds,
        rounds,
    })
}

/// How a learner from samples learns: its settings, where its episodes start (point masses)
/// and VQQL's quantiser.
#[derive(Clone, Debug, PartialEq)]
pub struct SampleLearning {
    /// Fuzzy Q-learning or VQQL.
    pub learner: Learner,
    /// The learning loop's settings (also VQQL's Q-learning).
    pub fql: FqlConfig,
    /// Where the point masses' episodes start.
    pub starts: Starts,
    /// VQQL's quantiser (VQQL only).
    pub vqql: Option<VqqlConfig>,
}

impl SampleLearning {
    /// The defaults of `learner` on the task of `config`: the environment's learning settings
    /// (see [`pointmass_task::default_fql_config`], [`khepera_task::default_fql_config`]),
    /// the configuration's discount, starts over the whole field, and for VQQL as many cells
    /// per agent as the grid has own-state cores (so that it has as many parameters as the
    /// additive fuzzy layout).
    pub fn defaults(config: &TrainConfig, learner: Learner) -> Result<Self, SimError> {
        check_available(&config.env, learner)?;
        let mut fql = match &config.env {
            EnvConfig::Pointmass(_) => pointmass_task::default_fql_config(),
            _ => khepera_task::default_fql_config(),
        };
        fql.gamma = config.solver.gamma;
        let g = &config.grid;
        let vqql = (learner == Learner::Vqql).then(|| VqqlConfig {
            cells: g.position_cores.len().pow(2) * g.velocity_cores.len().pow(2),
            ..VqqlConfig::default()
        });
        Ok(Self {
            learner,
            fql,
            starts: pointmass_task::default_starts(),
            vqql,
        })
    }
}

/// What a run of a learner from samples may change from [`SampleLearning::defaults`]: the
/// options of `fuzzyq train --learner fql|vqql` and of Python's `learn_from_samples`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SampleOptions {
    /// Number of episodes (default: the task's).
    pub episodes: Option<usize>,
    /// The update as printed in the paper (eqs 24-26) instead of the corrected one.
    pub literal: bool,
    /// VQQL's cells per agent (default: the own-state cores of the grid); VQQL only.
    pub cells: Option<usize>,
    /// Seed of exploration, starts, the plant's noise and VQQL's quantiser.
    pub seed: u64,
}

impl SampleLearning {
    /// [`defaults`](Self::defaults) changed by `options`, validated; `cells` for a learner
    /// other than VQQL is an error.
    pub fn with_options(
        config: &TrainConfig,
        learner: Learner,
        options: &SampleOptions,
    ) -> Result<Self, SimError> {
        if options.cells.is_some() && learner != Learner::Vqql {
            return Err(ConfigError::invalid("cells", "applies to the vqql learner only").into());
        }
        let mut learning = Self::defaults(config, learner)?;
        learning.fql.seed = options.seed;
        if let Some(n) = options.episodes {
            learning.fql.episodes = n;
        }
        if options.literal {
            learning.fql.update = fuzzyq_core::additive::Update::Literal;
        }
        if let Some(v) = &mut learning.vqql {
            v.cells = options.cells.unwrap_or(v.cells);
            v.seed = options.seed;
            v.validate()?;
        }
        learning.fql.validate()?;
        Ok(learning)
    }
}

/// Whether `learner` learns from samples on `env`; the error says why not.
fn check_available(env: &EnvConfig, learner: Learner) -> Result<(), ConfigError> {
    match (env, learner) {
        (_, Learner::Fqi | Learner::LearnedModel) => Err(ConfigError::invalid(
            "learner",
            "fqi and learned-model solve a model (train, train_learned), they are not \
             learners from samples of this kind",
        )),
        (EnvConfig::Pointmass(_), _) | (EnvConfig::Khepera(_), Learner::Fql) => Ok(()),
        (EnvConfig::Khepera(_), Learner::Vqql) => Err(ConfigError::invalid(
            "learner",
            "vqql is available for the pointmass environment only",
        )),
        (other, _) => Err(ConfigError::invalid(
            "learner",
            format!(
                "fql and vqql are available for the pointmass and khepera environments, not {}",
                other.name()
            ),
        )),
    }
}

/// What a learner from samples produced.
#[derive(Clone, Debug)]
pub struct Learned {
    /// The policy file's content.
    pub file: PolicyFile,
    /// The learning run (parameters, curve, convergence).
    pub outcome: FqlOutcome,
    /// VQQL's quantiser report.
    pub lloyd: Option<LloydReport>,
}

/// Learns the task of `config` from samples as `learning` says (see the [module docs](self));
/// `progress` sees every episode's record and may stop the run.
pub fn learn_from_samples(
    config: &TrainConfig,
    learning: &SampleLearning,
    progress: impl crate::learn::fql::Observer,
) -> Result<Learned, SimError> {
    config.validate()?;
    check_available(&config.env, learning.learner)?;
    learning.fql.validate()?;
    if let Some(v) = &learning.vqql {
        v.validate()?;
    }
    match (&config.env, learning.learner) {
        (EnvConfig::Khepera(k), Learner::Fql) => {
            let outcome = khepera_task::train_fql(k, &learning.fql, progress)?;
            let file = KheperaPolicyFile::from_outcome(k, &learning.fql, &outcome);
            Ok(Learned {
                file: PolicyFile::Khepera(file),
                outcome,
                lloyd: None,
            })
        }
        (EnvConfig::Pointmass(p), learner @ (Learner::Fql | Learner::Vqql)) => {
            let model = PointMass::new(p.clone())?;
            learning.starts.validate(&model)?;
            let (outcome, lloyd) = match (&learning.vqql, learner) {
                (Some(v), Learner::Vqql) => {
                    let (o, l) =
                        vqql::train_vqql(&model, &learning.starts, v, &learning.fql, progress)?;
                    (o, Some(l))
                }
                (_, Learner::Vqql) => {
                    return Err(ConfigError::invalid("vqql", "VQQL needs its settings").into());
                }
                _ => {
                    let g = &config.grid;
                    let features = pointmass_task::feature_space(
                        &model,
                        &g.position_cores,
                        &g.velocity_cores,
                    )?;
                    let o = pointmass_task::train_fql(
                        &model,
                        &features,
                        &learning.starts,
                        &learning.fql,
                        progress,
                    )?;
                    (o, None)
                }
            };
            let vqql = if learner == Learner::Vqql {
                learning.vqql.as_ref()
            } else {
                None
            };
            let file = PointMassPolicyFile::from_outcome(
                p,
                &learning.starts,
                &learning.fql,
                vqql,
                &outcome,
            );
            Ok(Learned {
                file: PolicyFile::PointMass(file),
                outcome,
                lloyd,
            })
        }
        _ => unreachable!("check_available refused the other pairs"),
    }
}
