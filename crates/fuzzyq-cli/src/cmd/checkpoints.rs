//! `fuzzyq train --checkpoint FILE [--checkpoint-every N]` and `--resume FILE`: writing a
//! training run's state as it goes, and continuing from it.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use fuzzyq_sim::io::checkpoint::{Checkpoint, RunState};
use fuzzyq_sim::learn::fql::{EpisodeRecord, Observer, Snapshot};

/// The checkpointing of one run.
pub(crate) struct Checkpoints {
    /// Where to write (`--checkpoint`).
    path: Option<PathBuf>,
    /// Write after every this many sweeps or episodes.
    every: usize,
    /// The run's settings, as the checkpoint keeps them.
    settings: String,
    /// The first write that failed: the run stops and reports it.
    failed: Option<fuzzyq_sim::io::checkpoint::CheckpointError>,
    /// How far the run got at the last checkpoint written (`"sweep 12"`).
    written: Option<String>,
}

impl Checkpoints {
    /// Checkpoints to `path` every `every` (default `default_every`) sweeps or episodes of a
    /// run with `settings`.
    pub(crate) fn new(
        path: Option<&Path>,
        every: Option<usize>,
        default_every: usize,
        settings: String,
    ) -> anyhow::Result<Self> {
        if every == Some(0) {
            anyhow::bail!("--checkpoint-every must be at least 1");
        }
        Ok(Self {
            path: path.map(Path::to_path_buf),
            every: every.unwrap_or(default_every),
            settings,
            failed: None,
            written: None,
        })
    }

    /// The state of `--resume FILE`, after checking that it continues the same learner
    /// (`fqi`: fuzzy Q-iteration, else a learner from samples, named `learner`) under these
    /// settings.
    pub(crate) fn resume(
        &self,
        path: Option<&Path>,
        fqi: bool,
        learner: &str,
    ) -> anyhow::Result<Option<RunState<'static>>> {
        let Some(path) = path else {
            return Ok(None);
        };
        let checkpoint = Checkpoint::load(path)?;
        match (&checkpoint.state, fqi) {
            (RunState::Fqi(_), false) => anyhow::bail!(
                "--resume: checkpoint {} continues fuzzy Q-iteration (--learner fqi), not {learner}",
                path.display()
            ),
            (RunState::Fql(_), true) => anyhow::bail!(
                "--resume: checkpoint {} continues a learner from samples, not --learner fqi",
                path.display()
            ),
            _ => {}
        }
        checkpoint.check_settings(&self.settings, path)?;
        Ok(Some(checkpoint.state))
    }

    /// After sweep or episode `count` (from 1): writes the run's `state` if one is due or the
    /// run is being `interrupted`, and says whether the run goes on (a failed write stops it).
    /// `state` is `None` when the run ends with this step, which then needs no checkpoint.
    pub(crate) fn after<'s>(
        &mut self,
        count: usize,
        interrupted: bool,
        state: impl FnOnce() -> Option<RunState<'s>>,
    ) -> ControlFlow<()> {
        let stop = if interrupted {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        };
        let Some(path) = &self.path else {
            return stop;
        };
        if !interrupted && !count.is_multiple_of(self.every) {
            return stop;
        }
        let Some(state) = state() else {
            return stop;
        };
        let progress = state.progress();
        let checkpoint = Checkpoint {
            settings: self.settings.as_str().into(),
            state,
        };
        match checkpoint.save(path) {
            Ok(()) => {
                self.written = Some(progress);
                stop
            }
            Err(e) => {
                self.failed = Some(e);
                ControlFlow::Break(())
            }
        }
    }

    /// The error of a failed checkpoint write, if any (the run stopped for it).
    pub(crate) fn failure(&mut self) -> Option<anyhow::Error> {
        self.failed.take().map(Into::into)
    }

    /// The message of a run stopped by Ctrl-C after `done` (`"12 sweeps"`).
    pub(crate) fn interrupted(&self, done: &str) -> String {
        match (&self.path, &self.written) {
            (Some(path), Some(at)) => format!(
                "interrupted after {done}; no policy was written; the run's state at {at} is in \
                 {p}: run the same command with --resume {p} to continue",
                p = path.display()
            ),
            _ => format!(
                "interrupted after {done}; no policy was written (with --checkpoint FILE a run \
                 can be continued)"
            ),
        }
    }
}

/// The observer of a learning run from samples: shows each episode (`progress`), stops on
/// Ctrl-C (`stop`), checkpoints, and continues from `resume`.
pub(crate) struct Episodes<'c, F> {
    pub(crate) progress: F,
    pub(crate) checkpoints: &'c mut Checkpoints,
    pub(crate) resume: Option<fuzzyq_sim::learn::fql::FqlState>,
    pub(crate) stop: &'c std::sync::atomic::AtomicBool,
}

impl<F: FnMut(&EpisodeRecord)> Observer for Episodes<'_, F> {
    fn episode(
        &mut self,
        record: &EpisodeRecord,
        snapshot: Option<&Snapshot<'_>>,
    ) -> ControlFlow<()> {
        (self.progress)(record);
        let interrupted = self.stop.load(std::sync::atomic::Ordering::SeqCst);
        self.checkpoints.after(record.episode + 1, interrupted, || {
            snapshot.map(|s| RunState::Fql(s.to_state()))
        })
    }

    fn resume(&mut self) -> Option<fuzzyq_sim::learn::fql::FqlState> {
        self.resume.take()
    }
}
