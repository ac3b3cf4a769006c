//! Training: a configuration in, a policy file's content out, for every learner.
//!
//! - [`train`]: joint fuzzy Q-iteration on the model (the paper's method), either operator;
//! - [`learn_from_samples`]: fuzzy Q-learning (the additive layout, corrected or printed
//!   update) on the point masses or the robots, and VQQL on the point masses, with the
//!   defaults of [`SampleLearning::defaults`].

use std::ops::ControlFlow;

use fuzzyq_core::Real;
use fuzzyq_core::solver::{
    self, Delta, IterationOperator, Precision, Progress, Solution, SweepRecord,
};

use crate::error::{ConfigError, SimError};
use crate::io::config::{EnvConfig, TrainConfig};
use crate::io::policy_file::{
    KheperaPolicyFile, PointMassPolicyFile, PolicyArtifact, PolicyFile, TrainSummary, Values,
};
use crate::learn::fql::{EpisodeRecord, FqlConfig, FqlOutcome};
use crate::learn::tasks::{khepera as khepera_task, pointmass as pointmass_task};
use crate::learn::vqql::{self, LloydReport, VqqlConfig};
use crate::model::EnvModel;
use crate::model::pointmass::{PointMass, Starts};

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
    }
}

/// Runs fuzzy Q-iteration as configured; `observer` sees every sweep and may stop the run
/// ([`SolveError::Interrupted`](fuzzyq_core::solver::SolveError::Interrupted)).
pub fn train(
    config: &TrainConfig,
    observer: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<PolicyArtifact, SimError> {
    config.validate()?;
    match config.solver.precision {
        Precision::F32 => Ok(artifact(
            config,
            solve::<f32>(config, observer)?,
            Values::F32,
        )),
        Precision::F64 => Ok(artifact(
            config,
            solve::<f64>(config, observer)?,
            Values::F64,
        )),
    }
}

fn solve<T: Real>(
    config: &TrainConfig,
    mut observer: impl FnMut(&Progress) -> ControlFlow<()>,
) -> Result<Solution<T>, SimError>
where
    EnvModel: fuzzyq_core::Model<T>,
{
    let model = config.build_model()?;
    let grid = config.grid::<T>()?;
    let solver_config = config.solver.solver_config();
    if config.solver.operator == IterationOperator::Values {
        return Ok(solver::solve(&model, &grid, &solver_config, observer)?);
    }
    // Busoniu's operator: theta stored; reported in the solver's terms (exact deltas).
    let start = std::time::Instant::now();
    let mut records: Vec<SweepRecord> = Vec::new();
    let mut bound = 0;
    let q = solver::solve_q(&model, &grid, &solver_config, |k, delta| {
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
        observer(&Progress {
            record,
            bound,
            xi: solver_config.xi,
        })
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
    }
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

/// Whether `learner` learns from samples on `env`; the error says why not.
fn check_available(env: &EnvConfig, learner: Learner) -> Result<(), ConfigError> {
    match (env, learner) {
        (_, Learner::Fqi) => Err(ConfigError::invalid(
            "learner",
            "fqi learns on the model (train), not from samples",
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
    progress: impl FnMut(&EpisodeRecord) -> ControlFlow<()>,
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
