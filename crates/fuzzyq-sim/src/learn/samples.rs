//! Transitions `(x, u, x', r)` and their collection by interacting with a plant.
//!
//! [`collect`] runs seeded episodes on a model's plant: each starts where `draw_start` says
//! (for the point masses, the task's random starts at rest) and takes actions as its
//! [`Exploration`] says (uniformly random, or epsilon-greedy with a policy the caller gives)
//! for a fixed number of steps, with the plant's process noise
//! ([`F64Model::add_process_noise`]). The learner sees only the recorded transitions; it never
//! calls the model's transition function. [`collect_khepera`] does the same on the Khepera
//! robots' rapier plant (contacts, and the configured wheel noise), from the task's random
//! starts. [`Transitions::from_columns`] takes a user's logged transitions instead.

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;

use crate::error::{ConfigError, SimError, require};
use crate::model::F64Model;
use crate::model::khepera::{self, KheperaModel, MAX_ROBOTS, N_ACTIONS};
use crate::world::KheperaWorld;

/// A policy for [`Exploration::EpsilonGreedy`]: writes each agent's action index at a state.
pub type GreedyActions<'a> = dyn FnMut(&[f64], &mut [usize]) -> Result<(), SimError> + 'a;

/// How the agents choose their actions while [`collect`] records them.
pub enum Exploration<'a> {
    /// Each agent takes one of its actions uniformly at random.
    Random,
    /// Each agent takes the action `greedy` gives it (per-agent action indices at the state)
    /// with probability `1 - epsilon`, a uniformly random one otherwise.
    EpsilonGreedy {
        /// Probability of a random action, per agent and step, in `[0, 1]`.
        epsilon: f64,
        /// Writes each agent's action index at a state (a policy's greedy joint action).
        greedy: &'a mut GreedyActions<'a>,
    },
}

impl std::fmt::Debug for Exploration<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Random => f.write_str("Random"),
            Self::EpsilonGreedy { epsilon, .. } => f
                .debug_struct("EpsilonGreedy")
                .field("epsilon", epsilon)
                .finish_non_exhaustive(),
        }
    }
}

impl Exploration<'_> {
    /// Writes every agent's action index at `x` (each of `n_actions`), drawing from `rng`.
    fn choose(
        &mut self,
        rng: &mut Pcg64Mcg,
        x: &[f64],
        n_actions: usize,
        out: &mut [usize],
    ) -> Result<(), SimError> {
        match self {
            Self::Random => {
                for a in out.iter_mut() {
                    *a = rng.random_range(0..n_actions);
                }
            }
            Self::EpsilonGreedy { epsilon, greedy } => {
                greedy(x, out)?;
                for a in out.iter_mut() {
                    if rng.random::<f64>() < *epsilon {
                        *a = rng.random_range(0..n_actions);
                    }
                }
            }
        }
        Ok(())
    }
}

/// Transitions `(x, u, x', r)`, stored column by column.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Transitions {
    state_dim: usize,
    action_dim: usize,
    x: Vec<f64>,
    u: Vec<f64>,
    next: Vec<f64>,
    reward: Vec<f64>,
}

impl Transitions {
    /// No transitions of states of length `state_dim` and action vectors of `action_dim`.
    #[must_use]
    pub fn new(state_dim: usize, action_dim: usize) -> Self {
        Self {
            state_dim,
            action_dim,
            ..Self::default()
        }
    }

    /// Transitions from flat row-major arrays (`n * state_dim` states and successors,
    /// `n * action_dim` actions, `n` rewards), all finite; errors name the array.
    pub fn from_columns(
        state_dim: usize,
        action_dim: usize,
        x: Vec<f64>,
        u: Vec<f64>,
        next: Vec<f64>,
        reward: Vec<f64>,
    ) -> Result<Self, ConfigError> {
        let n = reward.len();
        for (name, v, per) in [
            ("states", &x, state_dim),
            ("actions", &u, action_dim),
            ("next_states", &next, state_dim),
            ("rewards", &reward, 1),
        ] {
            require!(
                v.len() == n * per,
                name,
                format!(
                    "needs {} values ({n} transitions x {per}), got {}",
                    n * per,
                    v.len()
                ),
            );
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                return Err(ConfigError::invalid(
                    name,
                    format!("value {i} of transition {} is not finite", i / per.max(1)),
                ));
            }
        }
        Ok(Self {
            state_dim,
            action_dim,
            x,
            u,
            next,
            reward,
        })
    }

    /// Appends one transition.
    pub fn push(&mut self, x: &[f64], u: &[f64], next: &[f64], reward: f64) {
        self.x.extend_from_slice(x);
        self.u.extend_from_slice(u);
        self.next.extend_from_slice(next);
        self.reward.push(reward);
    }

    /// Number of transitions.
    #[must_use]
    pub fn len(&self) -> usize {
        self.reward.len()
    }

    /// Whether there are none.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.reward.is_empty()
    }

    /// Length of the states.
    #[must_use]
    pub fn state_dim(&self) -> usize {
        self.state_dim
    }

    /// Length of the action vectors.
    #[must_use]
    pub fn action_dim(&self) -> usize {
        self.action_dim
    }

    /// Every transition's state, action vector, successor (row-major) and reward.
    #[must_use]
    pub fn columns(&self) -> (&[f64], &[f64], &[f64], &[f64]) {
        (&self.x, &self.u, &self.next, &self.reward)
    }

    /// Transition `i`: state, action vector, successor, reward.
    #[must_use]
    pub fn get(&self, i: usize) -> (&[f64], &[f64], &[f64], f64) {
        let (e, d) = (self.state_dim, self.action_dim);
        (
            &self.x[i * e..(i + 1) * e],
            &self.u[i * d..(i + 1) * d],
            &self.next[i * e..(i + 1) * e],
            self.reward[i],
        )
    }

    /// Appends `other`'s transitions (of the same dimensions).
    pub fn append(&mut self, other: &Self) -> Result<(), ConfigError> {
        require!(
            (other.state_dim, other.action_dim) == (self.state_dim, self.action_dim),
            "transitions",
            format!(
                "cannot append transitions of {} state and {} action variables to ones of {} \
                 and {}",
                other.state_dim, other.action_dim, self.state_dim, self.action_dim
            ),
        );
        self.x.extend_from_slice(&other.x);
        self.u.extend_from_slice(&other.u);
        self.next.extend_from_slice(&other.next);
        self.reward.extend_from_slice(&other.reward);
        Ok(())
    }

    /// The first `n` transitions (all of them if there are fewer).
    #[must_use]
    pub fn truncated(&self, n: usize) -> Self {
        let n = n.min(self.len());
        let (e, d) = (self.state_dim, self.action_dim);
        Self {
            state_dim: e,
            action_dim: d,
            x: self.x[..n * e].to_vec(),
            u: self.u[..n * d].to_vec(),
            next: self.next[..n * e].to_vec(),
            reward: self.reward[..n].to_vec(),
        }
    }
}

/// How [`collect`] interacts with the plant.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Collection {
    /// Transitions to record, `>= 1`.
    pub samples: usize,
    /// Steps per episode, `>= 1` (an episode also ends early in a terminal state).
    pub episode_steps: usize,
    /// Seed of the starts, the actions and the plant's noise.
    pub seed: u64,
}

impl Collection {
    /// Checks the counts; errors name `samples` and `episode_steps`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        require!(self.samples >= 1, "samples", "must be at least 1");
        require!(
            self.episode_steps >= 1,
            "episode_steps",
            "must be at least 1"
        );
        Ok(())
    }
}

/// Records `collection.samples` transitions of `model`'s plant, the agents acting as
/// `exploration` says (see the [module docs](self)); `draw_start` writes an episode's start.
pub fn collect<M: F64Model + ?Sized>(
    model: &M,
    collection: &Collection,
    mut draw_start: impl FnMut(&mut Pcg64Mcg, &mut [f64]),
    exploration: &mut Exploration<'_>,
) -> Result<Transitions, SimError> {
    collection.validate()?;
    let e = model.state_dim();
    let actions = model.actions();
    let (n, per_agent) = (model.n_agents(), actions.dim());
    let mut out = Transitions::new(e, n * per_agent);
    let mut rng = Pcg64Mcg::seed_from_u64(collection.seed);
    let (mut x, mut next, mut u) = (vec![0.0; e], vec![0.0; e], vec![0.0; n * per_agent]);
    let mut chosen = vec![0; n];
    while out.len() < collection.samples {
        draw_start(&mut rng, &mut x);
        for _ in 0..collection.episode_steps {
            exploration.choose(&mut rng, &x, actions.len(), &mut chosen)?;
            for (agent, &a) in u.chunks_mut(per_agent).zip(&chosen) {
                agent.copy_from_slice(actions.action(a));
            }
            model.step(&x, &u, &mut next);
            model.add_process_noise(&mut next, &mut rng);
            let r = model.reward(&x, &u, fuzzyq_core::solver::Precision::F64);
            out.push(&x, &u, &next, r);
            std::mem::swap(&mut x, &mut next);
            if out.len() == collection.samples
                || (model.has_terminal_states() && model.is_terminal(&x))
            {
                break;
            }
        }
    }
    Ok(out)
}

/// Records `collection.samples` transitions of the Khepera robots of `model` on the rapier
/// plant: episodes from the task's random starts ([`khepera::random_starts`], seeded by
/// `collection.seed`), each robot taking one of its four actions per step as `exploration`
/// says, the plant adding its configured wheel noise (seeded from `collection.seed` too) and
/// its contacts. States are the robots' poses as the plant reports them; the reward is the
/// task's at the state.
pub fn collect_khepera(
    model: &KheperaModel,
    collection: &Collection,
    exploration: &mut Exploration<'_>,
) -> Result<Transitions, SimError> {
    collection.validate()?;
    let config = model.config();
    let n = config.agents;
    let episodes = collection.samples.div_ceil(collection.episode_steps);
    let starts = khepera::random_starts(config, episodes, collection.seed)?;
    // The plant's noise and the actions draw from distinct streams.
    let mut world = KheperaWorld::new(config, collection.seed ^ 0x5851_f42d_4c95_7f2d)?;
    let mut rng = Pcg64Mcg::seed_from_u64(collection.seed);
    let mut out = Transitions::new(3 * n, 2 * n);
    let (mut x, mut next, mut u) = (vec![0.0; 3 * n], vec![0.0; 3 * n], vec![0.0; 2 * n]);
    let mut wheels = [[0.0; 2]; MAX_ROBOTS];
    let mut chosen = [0; MAX_ROBOTS];
    let flatten = |poses: &[[f64; 3]], out: &mut [f64]| {
        for (p, o) in poses.iter().zip(out.chunks_exact_mut(3)) {
            o.copy_from_slice(p);
        }
    };
    for start in &starts {
        world.reset(start)?;
        flatten(world.poses(), &mut x);
        for _ in 0..collection.episode_steps {
            exploration.choose(&mut rng, &x, N_ACTIONS, &mut chosen[..n])?;
            for (i, w) in wheels[..n].iter_mut().enumerate() {
                *w = config.wheels(chosen[i]);
                u[2 * i..2 * i + 2].copy_from_slice(w);
            }
            world.step(&wheels[..n])?;
            flatten(world.poses(), &mut next);
            out.push(&x, &u, &next, model.reward_f64(&x));
            std::mem::swap(&mut x, &mut next);
            if out.len() == collection.samples {
                return Ok(out);
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::pointmass::PointMass;
    use crate::test_support::tiny_model as one_agent;

    fn run(model: &PointMass, exploration: &mut Exploration<'_>) -> Transitions {
        let c = Collection {
            samples: 400,
            episode_steps: 20,
            seed: 5,
        };
        collect(model, &c, |_, x| x.fill(1.0), exploration).unwrap()
    }

    /// Whether transition `i` took the action of index `a` (9 forces).
    fn took(model: &PointMass, d: &Transitions, i: usize, a: usize) -> bool {
        d.get(i).1 == F64Model::actions(model).action(a)
    }

    #[test]
    fn epsilon_greedy_follows_the_policy_at_epsilon_0_and_ignores_it_at_1() {
        let model = one_agent();
        let mut greedy = |_: &[f64], out: &mut [usize]| {
            out.fill(7);
            Ok(())
        };
        let mut at = |epsilon: f64| {
            let d = run(
                &model,
                &mut Exploration::EpsilonGreedy {
                    epsilon,
                    greedy: &mut greedy,
                },
            );
            (0..d.len()).filter(|&i| took(&model, &d, i, 7)).count()
        };
        assert_eq!(at(0.0), 400);
        // Uniform over 9 actions: about 44 of 400 take action 7 by chance.
        assert!(at(1.0) < 80);
        let half = at(0.5);
        assert!((190..=260).contains(&half), "{half}");
    }

    #[test]
    fn the_policy_sees_the_recorded_states() {
        let model = one_agent();
        let mut seen = Vec::new();
        let mut greedy = |x: &[f64], out: &mut [usize]| {
            seen.push(x.to_vec());
            out.fill(0);
            Ok(())
        };
        let d = run(
            &model,
            &mut Exploration::EpsilonGreedy {
                epsilon: 0.0,
                greedy: &mut greedy,
            },
        );
        assert_eq!(seen.len(), d.len());
        for (i, x) in seen.iter().enumerate() {
            assert_eq!(d.get(i).0, &x[..]);
        }
    }

    #[test]
    fn appending_needs_the_same_dimensions() {
        let model = one_agent();
        let mut a = run(&model, &mut Exploration::Random);
        let b = a.clone();
        a.append(&b).unwrap();
        assert_eq!(a.len(), 800);
        assert_eq!(a.get(400), b.get(0));
        let e = a.append(&Transitions::new(3, 2)).unwrap_err().to_string();
        assert!(e.contains("cannot append"), "{e}");
    }
}
