//! Rewards learned from transitions: the reward at every (core, joint action) pair of a grid,
//! for a system whose reward function is not known (a Gymnasium environment, say).
//!
//! # The estimator: the fuzzy averager
//! The reward at core `x_d` under joint action `u` is the membership-weighted mean of the
//! recorded rewards of the transitions that took `u`:
//! `rho[d, u] = sum_i mu_d(x_i) r_i / sum_i mu_d(x_i)` over those transitions. It is the
//! projection fuzzy Q-iteration itself uses (an averager, so it never amplifies noise), exact
//! for rewards that are linear between cores and a smoothing of others. A reward that does not
//! depend on the action (declared so) is averaged over all transitions at once: `M` times the
//! data per estimate.
//!
//! # Where no transition reached
//! A pair no transition activates takes its core's mean over every action; a core no
//! transition activates takes the **lowest** reward recorded. Pessimism keeps the greedy policy
//! inside the explored region rather than drawn to an unvisited state by a guess, and a later
//! round of collection (`rounds`) visits what the policy then reaches. Both are counted in the
//! [`RewardFit`].

use std::collections::HashMap;

use fuzzyq_core::{Membership, Partition, ProductPartition};
use serde::Serialize;

use crate::error::{ConfigError, require};
use crate::learn::fit::TaskShape;
use crate::learn::samples::Transitions;

/// How the rewards were estimated.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RewardFit {
    /// Whether a reward was estimated per joint action (else one per core).
    pub depends_on_action: bool,
    /// (core, joint action) pairs at a core some transition activates, but none with that
    /// action (they took their core's mean over every action).
    pub pairs_without_samples: usize,
    /// Cores no transition activates (they took [`fallback`](Self::fallback)).
    pub cores_without_samples: usize,
    /// The lowest reward recorded: the estimate where nothing was seen.
    pub fallback: f64,
    /// Root mean square of the recorded rewards minus the learned reward interpolated at the
    /// transitions' states.
    pub residual_rms: f64,
}

/// The rewards at every (core, joint action) pair of the grid `cores` (core-major in row-major
/// grid order, then joint action, agent 0 most significant), estimated from `data` (see the
/// [module docs](self)).
pub fn fit_rewards(
    shape: &TaskShape,
    cores: &[Vec<f64>],
    membership: Membership,
    data: &Transitions,
    depends_on_action: bool,
) -> Result<(Vec<f64>, RewardFit), ConfigError> {
    require!(!data.is_empty(), "transitions", "there are none");
    let parts = cores
        .iter()
        .map(|c| Partition::try_from_cores(&c[..]))
        .collect::<Result<Vec<_>, _>>()
        .map_err(|e| ConfigError::invalid("grid", e.to_string()))?;
    let grid = ProductPartition::from_partitions(&parts)
        .map_err(|e| ConfigError::invalid("grid", e.to_string()))?
        .with_membership(membership);
    let (vectors, dim) = shape.joint_vectors()?;
    let joint_of = joint_index(&vectors, dim);
    let (n, m) = (grid.n_cores(), vectors.len() / dim.max(1));
    let per = if depends_on_action { m } else { 1 };
    let (mut w, mut wr) = (vec![0.0; n * per], vec![0.0; n * per]);
    let (mut core_w, mut core_wr) = (vec![0.0; n], vec![0.0; n]);
    let mut joints = Vec::with_capacity(data.len());
    let mut fallback = f64::INFINITY;
    for i in 0..data.len() {
        let (x, u, _, r) = data.get(i);
        let j = joint_of(u).ok_or_else(|| {
            ConfigError::invalid(
                "transitions.actions",
                format!("row {i} is not one of the task's joint action vectors"),
            )
        })?;
        joints.push(j);
        fallback = fallback.min(r);
        let slot = if depends_on_action { j } else { 0 };
        grid.active_unchecked(x).for_each(|d, mu| {
            w[d * per + slot] += mu;
            wr[d * per + slot] += mu * r;
            core_w[d] += mu;
            core_wr[d] += mu * r;
        });
    }
    let mut rewards = vec![0.0; n * m];
    let (mut pairs_without, mut cores_without) = (0, 0);
    for d in 0..n {
        let core_mean = if core_w[d] > 0.0 {
            core_wr[d] / core_w[d]
        } else {
            cores_without += 1;
            fallback
        };
        for j in 0..m {
            let slot = d * per + if depends_on_action { j } else { 0 };
            rewards[d * m + j] = if w[slot] > 0.0 {
                wr[slot] / w[slot]
            } else {
                if core_w[d] > 0.0 {
                    pairs_without += 1;
                }
                core_mean
            };
        }
    }
    let mut sq = 0.0;
    for (i, &j) in joints.iter().enumerate() {
        let (x, _, _, r) = data.get(i);
        let mut est = 0.0;
        grid.active_unchecked(x)
            .for_each(|d, mu| est += mu * rewards[d * m + j]);
        sq += (est - r).powi(2);
    }
    let fit = RewardFit {
        depends_on_action,
        pairs_without_samples: pairs_without,
        cores_without_samples: cores_without,
        fallback,
        residual_rms: (sq / data.len() as f64).sqrt(),
    };
    Ok((rewards, fit))
}

/// The joint action index of an action vector that is exactly one of `vectors` (`dim` values
/// each).
fn joint_index(vectors: &[f64], dim: usize) -> impl Fn(&[f64]) -> Option<usize> + '_ {
    let key = |u: &[f64]| u.iter().map(|v| v.to_bits()).collect::<Vec<u64>>();
    let index: HashMap<Vec<u64>, usize> = vectors
        .chunks(dim.max(1))
        .enumerate()
        .map(|(j, u)| (key(u), j))
        .collect();
    move |u| index.get(&key(u)).copied()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn shape() -> TaskShape {
        TaskShape {
            bounds: vec![(0.0, 2.0)],
            periodic: vec![false],
            actions: vec![(vec![-1.0, 1.0], 1)],
        }
    }

    fn data(rows: &[(f64, f64, f64)]) -> Transitions {
        let mut t = Transitions::new(1, 1);
        for &(x, u, r) in rows {
            t.push(&[x], &[u], &[x], r);
        }
        t
    }

    #[test]
    fn averages_by_membership_and_action() {
        let cores = vec![vec![0.0, 1.0, 2.0]];
        // At 0.5: memberships 0.5 of cores 0 and 1.
        let d = data(&[(0.0, -1.0, 4.0), (0.5, -1.0, 2.0), (1.0, 1.0, 6.0)]);
        let (r, fit) = fit_rewards(&shape(), &cores, Membership::Triangular, &d, true).unwrap();
        // Core 0, action -1: (1 * 4 + 0.5 * 2) / 1.5.
        assert!((r[0] - 10.0 / 3.0).abs() < 1e-12);
        // Core 0, action 1: no sample; the core's mean over every action.
        assert!((r[1] - 10.0 / 3.0).abs() < 1e-12);
        // Core 1: action -1 from the sample at 0.5, action 1 from the one at 1.0.
        assert_eq!((r[2], r[3]), (2.0, 6.0));
        // Core 2: nothing reached it; the lowest reward.
        assert_eq!((r[4], r[5]), (2.0, 2.0));
        assert_eq!(
            (fit.pairs_without_samples, fit.cores_without_samples),
            (1, 1)
        );
        assert_eq!(fit.fallback, 2.0);
    }

    #[test]
    fn an_action_free_reward_pools_every_action() {
        let cores = vec![vec![0.0, 1.0, 2.0]];
        let d = data(&[(1.0, -1.0, 1.0), (1.0, 1.0, 3.0)]);
        let (r, fit) = fit_rewards(&shape(), &cores, Membership::Triangular, &d, false).unwrap();
        assert_eq!((r[2], r[3]), (2.0, 2.0));
        assert!(!fit.depends_on_action);
    }

    #[test]
    fn refuses_actions_outside_the_task() {
        let cores = vec![vec![0.0, 2.0]];
        let e = fit_rewards(
            &shape(),
            &cores,
            Membership::Triangular,
            &data(&[(1.0, 0.5, 0.0)]),
            true,
        )
        .unwrap_err();
        assert!(e.to_string().contains("row 0"), "{e}");
    }
}
