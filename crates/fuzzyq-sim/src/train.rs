//! Training: configuration in, [`PolicyArtifact`] out.

use std::ops::ControlFlow;

use fuzzyq_core::Real;
use fuzzyq_core::solver::{self, Delta, Grid, Progress, Solution, SweepRecord};

use crate::error::SimError;
use crate::io::config::{EnvConfig, IterationOperator, Precision, TrainConfig};
use crate::io::policy_file::{PolicyArtifact, TrainSummary, Values};
use crate::model::EnvModel;
use crate::model::classic::arm::Arm;
use crate::model::classic::carhill::CarHill;
use crate::model::classic::dcmotor::DcMotor;
use crate::model::classic::pendulum::Pendulum;
use crate::model::khepera::KheperaModel;
use crate::model::pointmass::PointMass;

/// Builds the model a configuration describes.
pub fn build_model(config: &TrainConfig) -> Result<EnvModel, SimError> {
    match &config.env {
        EnvConfig::Pointmass(p) => Ok(EnvModel::PointMass(PointMass::new(p.clone())?)),
        EnvConfig::Khepera(k) => Ok(EnvModel::Khepera(KheperaModel::new(k.clone())?)),
        EnvConfig::Dcmotor(c) => Ok(EnvModel::DcMotor(
            DcMotor::new(c.model.clone())?.with_actions(&c.actions)?,
        )),
        EnvConfig::Pendulum(c) => Ok(EnvModel::Pendulum(
            Pendulum::new(c.model.clone())?.with_actions(&c.actions)?,
        )),
        EnvConfig::Carhill(c) => Ok(EnvModel::CarHill(
            CarHill::new(c.model.clone())?.with_actions(&c.actions)?,
        )),
        EnvConfig::Arm(c) => Ok(EnvModel::Arm(
            Arm::new(c.model.clone())?.with_levels(&c.actions)?,
        )),
    }
}

/// The configuration's grid in precision `T`.
pub fn build_grid<T: Real>(config: &TrainConfig) -> Result<Grid<T>, SimError> {
    let cores = config
        .grid_cores()
        .into_iter()
        .map(|c| c.into_iter().map(T::from_f64).collect())
        .collect();
    Ok(Grid::new(cores)?.with_membership(config.grid.membership.to_core()))
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
    let model = build_model(config)?;
    let grid = build_grid::<T>(config)?;
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
        stop: q.stop,
        bound,
        path: solver::BackupPath::Generic,
        kernel: "q-values",
        multiply_adds_per_sweep: None,
        sweep_seconds: q.seconds,
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
