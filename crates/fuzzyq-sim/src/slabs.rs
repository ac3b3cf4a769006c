//! A training configuration's operator for computing sweeps in shards: one
//! [`SlabProblem`] per process (a cluster's worker, say) answers every pass of
//! [`fuzzyq_core::solver::Sweeps`] for a range of output slabs from that range's halo of input
//! slabs, and [`crate::train::train_on`] drives a run whose passes a backend assembles from
//! such answers. Every process that builds the problem from the same configuration builds
//! the same operator, so every shard has the bits of the single-process run.

use core::ops::Range;

use fuzzyq_core::Backup;
use fuzzyq_core::solver::{
    BackupPath, Grid, IterationOperator, Operator, Precision, SlabLayout, SolveError, SweepMode,
};

use crate::error::{ConfigError, SimError};
use crate::io::config::TrainConfig;
use crate::model::{EnvModel, Wide};

/// Refuses a configuration whose sweeps cannot run on slabs: the q-values operator (it
/// stores theta, not `V`), asynchronous sweeps (each slab reads the ones before it), and the
/// generic backup path (it has no slabs).
pub fn check_shardable(config: &TrainConfig) -> Result<(), ConfigError> {
    config.validate()?;
    let s = &config.solver;
    crate::error::require!(
        s.operator == IterationOperator::Values,
        "solver.operator",
        "must be \"values\" for sharded sweeps (\"q-values\" stores theta, not V)"
    );
    crate::error::require!(
        s.sweep == SweepMode::Synchronous,
        "solver.sweep",
        "must be \"sync\" for sharded sweeps (an asynchronous sweep reads the slabs it just \
         wrote)"
    );
    crate::error::require!(
        s.backup != BackupPath::Generic,
        "solver.backup",
        "must be \"block\" or \"auto\" for sharded sweeps (the generic path has no slabs)"
    );
    crate::error::require!(
        s.device == fuzzyq_core::solver::Device::Cpu,
        "solver.device",
        "must be \"cpu\" for sharded sweeps (the workers compute their slabs on their CPUs)"
    );
    Ok(())
}

/// What a [`SlabProblem`] owns: the model and the grid its operator borrows.
struct Owner<T> {
    model: EnvModel,
    grid: Grid<T>,
}

type Op<'a, T> = Operator<'a, T, EnvModel>;
type Op32<'a> = Op<'a, f32>;
type Op64<'a> = Op<'a, f64>;

self_cell::self_cell!(
    /// The single-precision operator, with what it borrows.
    struct Cell32 {
        owner: Owner<f32>,
        #[covariant]
        dependent: Op32,
    }
);

self_cell::self_cell!(
    /// The double-precision operator, with what it borrows.
    struct Cell64 {
        owner: Owner<f64>,
        #[covariant]
        dependent: Op64,
    }
);

/// The block operator of a training configuration, in its precision, built once per process
/// and asked for slabs ([`Operator::apply_slabs`] and its siblings) through
/// [`Self::with_f32`] or [`Self::with_f64`].
pub struct SlabProblem {
    cell: Cells,
    layout: SlabLayout,
}

enum Cells {
    F32(Cell32),
    F64(Cell64),
}

/// Builds the operator of `model` over `grid` as the solver would for `config`.
fn build<'a, T: Wide>(owner: &'a Owner<T>, config: &TrainConfig) -> Result<Op<'a, T>, SolveError> {
    let s = &config.solver;
    let backup = Backup {
        gamma: T::from_f64(s.gamma),
        absorbing_goal: s.absorbing_goal,
    };
    let op = Operator::new(&owner.model, owner.grid.view(), backup, s.backup)?;
    match s.kernel {
        Some(k) => op.with_kernel(k),
        None => Ok(op),
    }
}

impl SlabProblem {
    /// The operator of `config` ([`check_shardable`] first): its model, grid, discount,
    /// goal handling, backup path and kernel, in its precision.
    pub fn new(config: &TrainConfig) -> Result<Self, SimError> {
        check_shardable(config)?;
        let model = config.build_model()?;
        let cell = match config.solver.precision {
            Precision::F32 => {
                let owner = Owner {
                    model,
                    grid: config.grid::<f32>()?,
                };
                Cells::F32(Cell32::try_new(owner, |o| build(o, config))?)
            }
            Precision::F64 => {
                let owner = Owner {
                    model,
                    grid: config.grid::<f64>()?,
                };
                Cells::F64(Cell64::try_new(owner, |o| build(o, config))?)
            }
        };
        let layout = match &cell {
            Cells::F32(c) => c.borrow_dependent().slab_layout(),
            Cells::F64(c) => c.borrow_dependent().slab_layout(),
        };
        let layout = layout.ok_or_else(|| {
            ConfigError::invalid(
                "env",
                "declares no dynamics blocks, so its sweeps have no slabs to shard",
            )
        })?;
        Ok(Self { cell, layout })
    }

    /// How `V` is laid out in slabs.
    #[must_use]
    pub fn layout(&self) -> SlabLayout {
        self.layout
    }

    /// The precision of the values.
    #[must_use]
    pub fn precision(&self) -> Precision {
        match self.cell {
            Cells::F32(_) => Precision::F32,
            Cells::F64(_) => Precision::F64,
        }
    }

    /// `f` of the single-precision operator, or `None` in double precision.
    pub fn with_f32<R>(&self, f: impl FnOnce(&Op32<'_>) -> R) -> Option<R> {
        match &self.cell {
            Cells::F32(c) => Some(f(c.borrow_dependent())),
            Cells::F64(_) => None,
        }
    }

    /// `f` of the double-precision operator, or `None` in single precision.
    pub fn with_f64<R>(&self, f: impl FnOnce(&Op64<'_>) -> R) -> Option<R> {
        match &self.cell {
            Cells::F64(c) => Some(f(c.borrow_dependent())),
            Cells::F32(_) => None,
        }
    }

    /// The input slabs of output slabs `slabs` ([`Operator::input_slabs`]).
    pub fn input_slabs(&self, slabs: Range<usize>) -> Result<Vec<u32>, SolveError> {
        match &self.cell {
            Cells::F32(c) => c.borrow_dependent().input_slabs(slabs),
            Cells::F64(c) => c.borrow_dependent().input_slabs(slabs),
        }
    }
}
