//! The state of a solve between two sweeps: what [`solve_from`](super::solve_from) shows its
//! observer after every sweep and takes back to continue a run bit for bit.

use std::borrow::Cow;

use super::{Scheme, SweepRecord};

/// Everything a run of [`solve`](super::solve) carries from one sweep to the next, so that a
/// run continued from it ([`solve_from`](super::solve_from)) computes exactly the values,
/// sweep records and greedy actions of a run that was never stopped.
///
/// The vectors are in the solver's internal core order (see the [module docs](super)), which
/// depends only on the model's blocks and the grid: a state continues a run of the same
/// model, grid and [`SolverConfig`](super::SolverConfig) (the thread count and the kernel
/// instance may differ: every instance gives the same bits). The observer sees a borrowed
/// state (no copy); [`into_owned`](Self::into_owned) keeps one.
#[derive(Clone, Debug, PartialEq)]
#[cfg_attr(feature = "serde", derive(serde::Serialize, serde::Deserialize))]
pub struct SolverState<'a, T: Clone> {
    /// How the run iterates ([`Scheme::Value`] or [`Scheme::ModifiedPolicy`]).
    pub scheme: Scheme,
    /// `V` after the last sweep (shifted if that sweep was extrapolated), internal order.
    pub v: Cow<'a, [T]>,
    /// Synchronous value iteration: `V` after the sweep before the last (the stopping rule's
    /// bound reads it); empty otherwise.
    pub v_prev: Cow<'a, [T]>,
    /// Modified policy iteration: the greedy joint actions of the last full backup, which the
    /// evaluation sweeps follow; empty otherwise.
    pub policy: Cow<'a, [u32]>,
    /// Synchronous value iteration: the constant the extrapolation added to `v` after the
    /// last sweep (0 if none).
    pub shift: f64,
    /// Modified policy iteration: evaluation sweeps still allowed under `policy` before the
    /// next full backup (0: a full backup is next).
    pub evaluations_left: usize,
    /// Modified policy iteration: the half-span at which the evaluation sweeps stop.
    pub evaluation_tolerance: f64,
    /// The exact change of the last sweep whose change is known exactly (`NaN` if none).
    pub final_delta: f64,
    /// Seconds spent in sweeps so far.
    pub sweep_seconds: f64,
    /// The part of `sweep_seconds` spent in evaluation sweeps.
    pub evaluation_seconds: f64,
    /// Every sweep so far; its length is the number of sweeps done.
    pub records: Cow<'a, [SweepRecord]>,
}

impl<T: Clone> SolverState<'_, T> {
    /// An owned copy, independent of the run that showed it.
    #[must_use]
    pub fn into_owned(self) -> SolverState<'static, T> {
        SolverState {
            scheme: self.scheme,
            v: Cow::Owned(self.v.into_owned()),
            v_prev: Cow::Owned(self.v_prev.into_owned()),
            policy: Cow::Owned(self.policy.into_owned()),
            shift: self.shift,
            evaluations_left: self.evaluations_left,
            evaluation_tolerance: self.evaluation_tolerance,
            final_delta: self.final_delta,
            sweep_seconds: self.sweep_seconds,
            evaluation_seconds: self.evaluation_seconds,
            records: Cow::Owned(self.records.into_owned()),
        }
    }

    /// A view of this state that borrows its buffers (no copy, whether they are borrowed or
    /// owned here: a checkpoint of a GPU run, whose `V` was read back, writes this).
    #[must_use]
    pub fn borrowed(&self) -> SolverState<'_, T> {
        SolverState {
            scheme: self.scheme,
            v: Cow::Borrowed(&self.v),
            v_prev: Cow::Borrowed(&self.v_prev),
            policy: Cow::Borrowed(&self.policy),
            shift: self.shift,
            evaluations_left: self.evaluations_left,
            evaluation_tolerance: self.evaluation_tolerance,
            final_delta: self.final_delta,
            sweep_seconds: self.sweep_seconds,
            evaluation_seconds: self.evaluation_seconds,
            records: Cow::Borrowed(&self.records),
        }
    }

    /// Sweeps done (full backups and evaluation sweeps).
    #[must_use]
    pub fn sweeps(&self) -> usize {
        self.records.len()
    }

    /// Seconds of the run so far (at the end of its last sweep).
    #[must_use]
    pub fn seconds(&self) -> f64 {
        self.records.last().map_or(0.0, |r| r.seconds)
    }
}
