//! Continuing a learning run: the state [`learn`](super::learn) carries from one episode to
//! the next ([`FqlState`]), shown to the [`Observer`] after every episode and taken back to
//! continue the run bit for bit.

use std::collections::VecDeque;
use std::ops::ControlFlow;

use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use super::{EpisodeRecord, FqlConfig, WindowLog};
use crate::error::ConfigError;

/// What a [`learn`](super::learn) run reports to after every episode, and may continue from.
///
/// Every closure `FnMut(&EpisodeRecord) -> ControlFlow<()>` is an observer that sees the
/// records only and starts afresh; implement the trait to keep [`Snapshot`]s or to continue
/// a run ([`resume`](Self::resume)).
pub trait Observer {
    /// Sees episode `record.episode`'s record and, unless the run ends with it, a snapshot of
    /// the run's state after it; [`ControlFlow::Break`] stops the run.
    fn episode(
        &mut self,
        record: &EpisodeRecord,
        snapshot: Option<&Snapshot<'_>>,
    ) -> ControlFlow<()>;

    /// The state to continue from, asked once before the first episode (`None`: start
    /// afresh).
    fn resume(&mut self) -> Option<FqlState> {
        None
    }
}

impl<F: FnMut(&EpisodeRecord) -> ControlFlow<()>> Observer for F {
    fn episode(&mut self, record: &EpisodeRecord, _: Option<&Snapshot<'_>>) -> ControlFlow<()> {
        self(record)
    }
}

/// The state of a learning run between two episodes: its parameters, the learning RNG's
/// state, the convergence test's window, the episodes' records and counters. A run of the
/// same environment, features and [`FqlConfig`] continued from it learns exactly what the
/// uninterrupted run learns.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FqlState {
    phi: Vec<Vec<f64>>,
    rng: Pcg64Mcg,
    /// `(agent, index, value before the update)` over the window, oldest first.
    window: Vec<(usize, usize, f64)>,
    /// Entries of `window` per logged episode, oldest first.
    window_episodes: Vec<usize>,
    curve: Vec<EpisodeRecord>,
    converged_at: Option<usize>,
    steps_total: usize,
    moved: bool,
}

impl FqlState {
    /// Episodes done.
    #[must_use]
    pub fn episodes(&self) -> usize {
        self.curve.len()
    }

    /// Checks that the state continues a run with parameters shaped like `phi` under
    /// `config`; errors name what does not fit.
    pub(super) fn check(&self, phi: &[Vec<f64>], config: &FqlConfig) -> Result<(), ConfigError> {
        let bad = |what: &str| Err(ConfigError::invalid("checkpoint", what));
        let shapes = |p: &[Vec<f64>]| p.iter().map(Vec::len).collect::<Vec<_>>();
        if shapes(&self.phi) != shapes(phi) {
            return bad("its parameters have another shape than this run's");
        }
        if self.phi.iter().flatten().any(|x| !x.is_finite()) {
            return bad("its parameters are not finite");
        }
        if self.curve.is_empty() || self.curve.len() >= config.episodes {
            return bad("its episode count does not leave episodes to run");
        }
        if self.curve.iter().enumerate().any(|(i, r)| r.episode != i) {
            return bad("its episode records are not numbered 0, 1, ...");
        }
        let logged: usize = self.window_episodes.iter().sum();
        let in_range = self
            .window
            .iter()
            .all(|&(a, k, _)| phi.get(a).is_some_and(|p| k < p.len()));
        if self.window_episodes.len() > config.window || logged != self.window.len() || !in_range {
            return bad("its convergence window does not fit the settings");
        }
        Ok(())
    }

    /// Moves the state into the run's variables.
    pub(super) fn restore(self, run: &mut Restored<'_>) {
        *run.phi = self.phi;
        *run.rng = self.rng;
        run.log.entries = self.window.into();
        run.log.per_episode = self.window_episodes.into();
        run.log.open = 0;
        *run.curve = self.curve;
        *run.converged_at = self.converged_at;
        *run.steps_total = self.steps_total;
        *run.moved = self.moved;
    }
}

/// The run's variables a [`FqlState`] restores.
pub(super) struct Restored<'a> {
    pub phi: &'a mut Vec<Vec<f64>>,
    pub rng: &'a mut Pcg64Mcg,
    pub log: &'a mut WindowLog,
    pub curve: &'a mut Vec<EpisodeRecord>,
    pub converged_at: &'a mut Option<usize>,
    pub steps_total: &'a mut usize,
    pub moved: &'a mut bool,
}

/// A borrowed view of a run's state after an episode; [`to_state`](Self::to_state) copies it.
pub struct Snapshot<'a> {
    pub(super) phi: &'a [Vec<f64>],
    pub(super) rng: &'a Pcg64Mcg,
    pub(super) window: &'a VecDeque<(usize, usize, f64)>,
    pub(super) window_episodes: &'a VecDeque<usize>,
    pub(super) curve: &'a [EpisodeRecord],
    pub(super) converged_at: Option<usize>,
    pub(super) steps_total: usize,
    pub(super) moved: bool,
}

impl Snapshot<'_> {
    /// Episodes done.
    #[must_use]
    pub fn episodes(&self) -> usize {
        self.curve.len()
    }

    /// An owned copy of the state.
    #[must_use]
    pub fn to_state(&self) -> FqlState {
        FqlState {
            phi: self.phi.to_vec(),
            rng: self.rng.clone(),
            window: self.window.iter().copied().collect(),
            window_episodes: self.window_episodes.iter().copied().collect(),
            curve: self.curve.to_vec(),
            converged_at: self.converged_at,
            steps_total: self.steps_total,
            moved: self.moved,
        }
    }
}
