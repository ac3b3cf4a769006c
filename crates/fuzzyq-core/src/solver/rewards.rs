//! The rewards (and absorbing goal flags) of every core, evaluated once as an operator is
//! prepared, on every thread.
//!
//! A reward of the state alone ([`Model::reward_depends_on_action`] false) is evaluated once
//! per core; one that also ignores some state variables ([`Model::reward_depends_on_state`]:
//! the robots' reward reads their positions, not their headings) once per class of cores that
//! agree on the others, and copied to the rest: on the block path, 130,321 evaluations for the
//! robots' 37.7M cores. The copies are the values a per-core evaluation would give, bit for
//! bit, as long as the model's declaration is true.

use super::*;

impl<T: Real, M: Model<T> + Sync + ?Sized> Operator<'_, T, M> {
    /// Whether each core (internal order) is a goal, on every thread (`coords` from
    /// [`Self::block_coords`]).
    fn goal_flags(&self, coords: &[Vec<T>]) -> Vec<bool> {
        let e = self.state_dim();
        let mut goal = vec![false; self.n_cores()];
        par::for_each_chunk_mut(
            &mut goal,
            STATE_CHUNK,
            || vec![T::ZERO; e],
            |x, ci, chunk| {
                let first = ci * STATE_CHUNK;
                self.for_each_core_state(coords, first..first + chunk.len(), x, |i, x| {
                    chunk[i - first] = self.model.is_goal(x);
                });
            },
        );
        goal
    }

    /// Every core's reward where it depends on the state alone (else only the rewards'
    /// bound, over every core and joint action), or the bound of the model's reward table;
    /// and the goal flags with an absorbing goal. Errors on a reward that is not finite.
    pub(super) fn prepare_rewards(&mut self) -> Result<(), SolveError> {
        let n = self.n_cores();
        let e = self.state_dim();
        let a = self.joint.dim();
        let absorbing = self.backup.absorbing_goal;
        if let Some(t) = &self.reward_table {
            let (bound, finite) = bound_and_finiteness(t);
            if !finite {
                return Err(SolveError::NonFinite { what: "reward" });
            }
            self.reward_bound = bound;
            if absorbing {
                self.goal = self.goal_flags(&self.block_coords());
            }
            return Ok(());
        }
        let depends = self.model.reward_depends_on_action();
        // Straight into the per-core reward vector (state-only rewards; none otherwise, only
        // the bound), each task reducing its own bound and finiteness: no per-core tuples
        // (24 bytes a core, 0.9 GB on the robots' 37.7M cores).
        let this = &*self;
        let coords = self.block_coords();
        let mut rewards = vec![T::ZERO; if depends { 0 } else { n }];
        let m = if depends { self.joint.n_joint() } else { 1 };
        // The rewards of the cores `range` to `out` (if given), and their bound and finiteness.
        let rewards_of = |(x, u): &mut (Vec<T>, Vec<T>),
                          range: core::ops::Range<usize>,
                          mut out: Option<&mut [T]>| {
            let (mut rmax, mut finite) = (0.0f64, true);
            let first = range.start;
            // A state-only reward sees joint action 0, set once.
            this.joint.vector_unchecked(0, u);
            this.for_each_core_state(&coords, range, x, |i, x| {
                for j in 0..m {
                    if depends {
                        this.joint.vector_unchecked(j, u);
                    }
                    let r = this.model.reward(x, u);
                    finite &= r.is_finite();
                    if j == 0
                        && let Some(o) = out.as_deref_mut()
                    {
                        o[i - first] = r;
                    }
                    rmax = rmax.max(r.to_f64().abs());
                }
            });
            (rmax, finite)
        };
        let init = || (vec![T::ZERO; e], vec![T::ZERO; a]);
        let both = |l: (f64, bool), r: (f64, bool)| (l.0.max(r.0), l.1 && r.1);
        let (bound, finite) = if depends {
            par::map_reduce(
                n,
                STATE_CHUNK,
                (0.0, true),
                |range| rewards_of(&mut init(), range, None),
                both,
            )
        } else if let Some(pooled) = self.rewards_by_class(&coords, &mut rewards) {
            pooled
        } else {
            par::map_reduce_chunks_mut(
                &mut rewards,
                STATE_CHUNK,
                init,
                |w, ci, chunk| {
                    let range = ci * STATE_CHUNK..ci * STATE_CHUNK + chunk.len();
                    rewards_of(w, range, Some(chunk))
                },
                (0.0, true),
                both,
            )
        };
        let goal = if absorbing {
            self.goal_flags(&coords)
        } else {
            Vec::new()
        };
        if !finite {
            return Err(SolveError::NonFinite { what: "reward" });
        }
        self.reward_bound = bound;
        self.goal = goal;
        if !depends {
            self.rewards = Some(rewards);
        }
        Ok(())
    }

    /// The state-only rewards of every core (internal order) into `out`, evaluated once per
    /// class of block cores that agree on the state variables the reward reads, and their
    /// bound and finiteness; `None` (nothing written) where the reward reads every variable or
    /// the path has no blocks.
    pub(super) fn rewards_by_class(&self, coords: &[Vec<T>], out: &mut [T]) -> Option<(f64, bool)> {
        let Path::Block(b) = &self.path else {
            return None;
        };
        let (e, a) = (self.state_dim(), self.joint.dim());
        let reads = |d: usize| self.model.reward_depends_on_state(d);
        if (0..e).all(reads) {
            return None;
        }
        let classes = b.core_classes(coords, reads);
        let mut by_class = vec![T::ZERO; classes.iter().map(|c| c.n_classes()).product()];
        par::for_each_chunk_mut(
            &mut by_class,
            STATE_CHUNK,
            || (vec![T::ZERO; e], vec![T::ZERO; a]),
            |(x, u), ci, chunk| {
                let first = ci * STATE_CHUNK;
                // A state-only reward sees joint action 0.
                self.joint.vector_unchecked(0, u);
                b.for_each_class_state(&classes, first..first + chunk.len(), x, |k, x| {
                    chunk[k - first] = self.model.reward(x, u);
                });
            },
        );
        b.spread(&classes, &by_class, out);
        // Every class holds a core, so the classes' bound and finiteness are the cores'.
        Some(bound_and_finiteness(&by_class))
    }
}

/// The largest `|r|` of `rewards` and whether they are all finite.
fn bound_and_finiteness<T: Real>(rewards: &[T]) -> (f64, bool) {
    let bound = rewards.iter().fold(0.0f64, |m, r| m.max(r.to_f64().abs()));
    (bound, rewards.iter().all(|r| r.is_finite()))
}
