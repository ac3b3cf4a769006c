//! The additive Q-function of the learners from samples (the paper's eqs 12-13 read per
//! agent): its parameters, greedy actions and values, and the sample update, whose arithmetic
//! is the core's [`fuzzyq_core::additive`] (the one layout and index convention:
//! `phi[i][d * M_i + u_i]`).

use fuzzyq_core::EvalError;
use fuzzyq_core::additive::{self, Td, Update};
use fuzzyq_core::error::check_len;
use fuzzyq_core::partition::ActiveCores;
use serde::{Deserialize, Deserializer, Serialize};

use crate::error::{ConfigError, SimError, discount, positive, require};
use crate::learn::features::FeatureSpace;

/// One transition for [`AdditiveQ::update`]: per-agent observations before and after, the
/// joint action taken, the reward and whether the next state is absorbing.
#[derive(Clone, Copy, Debug)]
pub struct Sample<'a> {
    /// Observations `obs_i(x_k)`, one slice per agent.
    pub obs: &'a [&'a [f64]],
    /// The joint action `u_k`, one index per agent.
    pub actions: &'a [usize],
    /// The reward `r_{k+1}`.
    pub reward: f64,
    /// Observations `obs_i(x_{k+1})`, one slice per agent.
    pub next_obs: &'a [&'a [f64]],
    /// `x_{k+1}` is absorbing: no bootstrap.
    pub terminal: bool,
}

/// The additive fuzzy Q-function (`docs/design.md`, section 2):
/// `Q(x, u) = sum_i sum_d mu_d(obs_i) phi[i][d * M_i + u_i]`.
///
/// Serialised with its feature space, action counts and parameters; deserialising validates
/// their shapes.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct AdditiveQ {
    pub(crate) features: FeatureSpace,
    pub(crate) actions: Vec<usize>,
    pub(crate) phi: Vec<Vec<f64>>,
}

impl<'de> Deserialize<'de> for AdditiveQ {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Data {
            features: FeatureSpace,
            actions: Vec<usize>,
            phi: Vec<Vec<f64>>,
        }
        let data = Data::deserialize(d)?;
        Self::from_params(data.features, data.actions, data.phi).map_err(serde::de::Error::custom)
    }
}

/// One transition as the learning loop sees it: the active cores before and after, the
/// per-agent action values before (`q`, at `x_k`) and after (`q_next`, at `x_{k+1}`, before
/// the update) and the joint action.
pub(crate) struct Step<'s> {
    pub(crate) cur: &'s [ActiveCores<f64>],
    pub(crate) next: &'s [ActiveCores<f64>],
    pub(crate) q: &'s [Vec<f64>],
    pub(crate) q_next: &'s [Vec<f64>],
    pub(crate) actions: &'s [usize],
    pub(crate) reward: f64,
    pub(crate) terminal: bool,
}

/// How a sample update changes the parameters: the rule, the discount, the step size and the
/// box `[-bound, bound]` the parameters are projected onto.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rates {
    pub(crate) rule: Update,
    pub(crate) gamma: f64,
    pub(crate) alpha: f64,
    pub(crate) bound: f64,
}

/// Applies one sample update in place with the core's [`additive`] update: returns the TD
/// error `delta` (corrected) or the bracket `r + beta - Gamma` (literal), or `None`, leaving
/// `phi` untouched, when the update is not finite. Each changed parameter is then projected
/// onto `[-bound, bound]` (an infinite `bound` projects nothing). `log(agent, index,
/// old_value)` is called before each parameter is overwritten.
pub(crate) fn td_update(
    rates: Rates,
    phi: &mut [Vec<f64>],
    m: &[usize],
    step: &Step<'_>,
    mut log: impl FnMut(usize, usize, f64),
) -> Option<f64> {
    let Rates {
        rule,
        gamma,
        alpha,
        bound,
    } = rates;
    let mut td = Td::default();
    for (i, &u) in step.actions.iter().enumerate() {
        td.add_agent(step.q[i][u], &step.q_next[i], u, &step.next[i]);
    }
    let inc = rule.increment(&td, step.reward, step.terminal, gamma, alpha)?;
    let finite = (0..phi.len()).all(|i| {
        let cores = inc.cores(&step.cur[i], &step.next[i]);
        inc.keeps_finite(&phi[i], m[i], cores, step.actions[i])
    });
    if !finite {
        return None;
    }
    for (i, phi_i) in phi.iter_mut().enumerate() {
        let cores = inc.cores(&step.cur[i], &step.next[i]);
        inc.apply_within(phi_i, m[i], cores, step.actions[i], bound, |k, old| {
            log(i, k, old);
        });
    }
    Some(inc.error)
}

impl AdditiveQ {
    /// All parameters zero (eq 23), for `actions[i] = M_i` actions per agent.
    pub fn new(features: FeatureSpace, actions: Vec<usize>) -> Result<Self, SimError> {
        let total = features.n_params(&actions)?;
        let mut phi = Vec::with_capacity(features.n_agents());
        for (&n, &m) in features.n_cores.iter().zip(&actions) {
            let mut table = Vec::new();
            table.try_reserve_exact(n * m).map_err(|_| {
                ConfigError::invalid(
                    "features",
                    format!("{total} parameters do not fit in memory"),
                )
            })?;
            table.resize(n * m, 0.0);
            phi.push(table);
        }
        Ok(Self {
            features,
            actions,
            phi,
        })
    }

    /// Given parameters: `phi[i]` has `N_i * M_i` finite values, row-major by core
    /// (`phi[i][d * M_i + u_i]`).
    pub fn from_params(
        features: FeatureSpace,
        actions: Vec<usize>,
        phi: Vec<Vec<f64>>,
    ) -> Result<Self, SimError> {
        features.n_params(&actions)?;
        require!(
            phi.len() == features.n_agents(),
            "phi",
            format!(
                "expected one table per agent ({}), found {}",
                features.n_agents(),
                phi.len()
            ),
        );
        for (i, table) in phi.iter().enumerate() {
            let expected = features.n_cores[i] * actions[i];
            require!(
                table.len() == expected,
                &format!("phi[{i}]"),
                format!(
                    "expected {} cores x {} actions = {expected} values, found {}",
                    features.n_cores[i],
                    actions[i],
                    table.len()
                ),
            );
            if let Some(k) = table.iter().position(|v| !v.is_finite()) {
                return Err(ConfigError::invalid(
                    format!("phi[{i}]"),
                    format!("value {k} is not a finite number"),
                )
                .into());
            }
        }
        Ok(Self {
            features,
            actions,
            phi,
        })
    }

    /// The fuzzy partitions of the agents' observations.
    #[must_use]
    pub fn features(&self) -> &FeatureSpace {
        &self.features
    }

    /// Number of agents `n`.
    #[must_use]
    pub fn n_agents(&self) -> usize {
        self.actions.len()
    }

    /// Action counts `M_i`, one per agent.
    #[must_use]
    pub fn actions(&self) -> &[usize] {
        &self.actions
    }

    /// The parameters: `params()[i][d * M_i + u_i]` for agent `i`, core `d`, action `u_i`.
    #[must_use]
    pub fn params(&self) -> &[Vec<f64>] {
        &self.phi
    }

    /// The active cores of agent `agent` at `obs` (checked length, finite values).
    fn active(&self, agent: usize, obs: &[f64]) -> Result<ActiveCores<f64>, SimError> {
        self.features.active(agent, obs)
    }

    fn check_joint(&self, obs: &[&[f64]], what: &'static str) -> Result<(), EvalError> {
        check_len(what, self.n_agents(), obs.len())
    }

    fn check_actions(&self, actions: &[usize]) -> Result<(), EvalError> {
        check_len("joint action", self.n_agents(), actions.len())?;
        for (&u, &m) in actions.iter().zip(&self.actions) {
            if u >= m {
                return Err(EvalError::OutOfRange {
                    what: "action",
                    index: u,
                    len: m,
                });
            }
        }
        Ok(())
    }

    /// Per-action values of agent `agent`'s term at its observation `obs`:
    /// `out[u] = sum_d mu_d(obs) phi[agent][d * M + u]` (`out` has length `M_agent`).
    pub fn q_agent(&self, agent: usize, obs: &[f64], out: &mut [f64]) -> Result<(), SimError> {
        let active = self.active(agent, obs)?;
        let m = self.actions[agent];
        check_len("action values", m, out.len())?;
        additive::q_values_unchecked(&active, &self.phi[agent], out);
        Ok(())
    }

    /// Agent `agent`'s greedy action at `obs` (the lowest index on ties).
    pub fn greedy(&self, agent: usize, obs: &[f64]) -> Result<usize, SimError> {
        Ok(self.greedy_with_value(agent, obs)?.0)
    }

    /// Agent `agent`'s greedy action at `obs` and its value.
    pub(crate) fn greedy_with_value(
        &self,
        agent: usize,
        obs: &[f64],
    ) -> Result<(usize, f64), SimError> {
        let active = self.active(agent, obs)?;
        Ok(additive::greedy(
            &active,
            &self.phi[agent],
            self.actions[agent],
        )?)
    }

    /// The greedy joint action: each agent's [`greedy`](Self::greedy) action, into `out`.
    pub fn greedy_joint(&self, obs: &[&[f64]], out: &mut [usize]) -> Result<(), SimError> {
        self.check_joint(obs, "observations")?;
        check_len("joint action", self.n_agents(), out.len())?;
        for (i, (o, u)) in obs.iter().zip(out.iter_mut()).enumerate() {
            *u = self.greedy(i, o)?;
        }
        Ok(())
    }

    /// `Q(x, u)`: the sum over agents of their terms at `obs[i]` and action `actions[i]`.
    pub fn q(&self, obs: &[&[f64]], actions: &[usize]) -> Result<f64, SimError> {
        self.check_joint(obs, "observations")?;
        self.check_actions(actions)?;
        let mut total = 0.0;
        for (i, (o, &u)) in obs.iter().zip(actions).enumerate() {
            let active = self.active(i, o)?;
            let (m, phi) = (self.actions[i], &self.phi[i]);
            active.for_each(|d, w| total += w * phi[d * m + u]);
        }
        Ok(total)
    }

    /// `max_u Q(x, u)`: the sum over agents of their largest action value.
    pub fn value(&self, obs: &[&[f64]]) -> Result<f64, SimError> {
        self.check_joint(obs, "observations")?;
        let mut total = 0.0;
        for (i, o) in obs.iter().enumerate() {
            total += self.greedy_with_value(i, o)?.1;
        }
        Ok(total)
    }

    /// Applies one sample update ([`fuzzyq_core::additive::update`]) with discount `gamma` in
    /// `[0, 1)` and step size `alpha > 0`. Returns the TD error `delta` ([`Update::Corrected`])
    /// or the bracket `r + beta - Gamma` ([`Update::Literal`]). An update that would make a
    /// parameter non-finite is refused and leaves the parameters unchanged.
    pub fn update(
        &mut self,
        rule: Update,
        sample: &Sample<'_>,
        gamma: f64,
        alpha: f64,
    ) -> Result<f64, SimError> {
        discount("gamma", gamma)?;
        positive("alpha", alpha)?;
        if !sample.reward.is_finite() {
            return Err(EvalError::NotFinite {
                what: "reward",
                index: 0,
            }
            .into());
        }
        self.check_joint(sample.obs, "observations")?;
        self.check_joint(sample.next_obs, "next observations")?;
        self.check_actions(sample.actions)?;
        let mut agents = Vec::with_capacity(self.n_agents());
        for (i, phi) in self.phi.iter_mut().enumerate() {
            agents.push(additive::Agent {
                phi,
                n_actions: self.actions[i],
                cur: self.features.active(i, sample.obs[i])?,
                next: self.features.active(i, sample.next_obs[i])?,
                action: sample.actions[i],
            });
        }
        additive::update(
            rule,
            &mut agents,
            sample.reward,
            sample.terminal,
            gamma,
            alpha,
        )?
        .ok_or_else(|| {
            EvalError::NotFinite {
                what: "parameter update",
                index: 0,
            }
            .into()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sample both hand-computed updates take on [`hand_q`].
    const HAND_SAMPLE: Sample<'static> = Sample {
        obs: &[&[0.25], &[0.5]],
        actions: &[1, 2],
        reward: 1.0,
        next_obs: &[&[1.5], &[1.0]],
        terminal: false,
    };

    /// Two agents: agent 0 on cores [0, 1, 2] with 2 actions, agent 1 on cores [0, 1] with 3.
    fn hand_q() -> AdditiveQ {
        let features =
            FeatureSpace::new(vec![vec![vec![0.0, 1.0, 2.0]], vec![vec![0.0, 1.0]]]).unwrap();
        AdditiveQ::from_params(
            features,
            vec![2, 3],
            vec![
                vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0],
                vec![0.5, -1.0, 2.0, 1.5, 0.0, -0.5],
            ],
        )
        .unwrap()
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() <= 1e-12
    }

    #[test]
    fn corrected_update_by_hand() {
        // x_k: agent 0 at 0.25 (cores 0, 1 with 0.75, 0.25), agent 1 at 0.5 (0.5, 0.5).
        // Q(x_k, (1, 2)) = (0.75*2 + 0.25*4) + (0.5*2 + 0.5*(-0.5)) = 2.5 + 0.75 = 3.25.
        // x_{k+1}: agent 0 at 1.5 (cores 1, 2: values (4, 5), max 5), agent 1 at 1.0 (core 1:
        // values (1.5, 0, -0.5), max 1.5). max Q(x_{k+1}) = 6.5.
        // delta = 1 + 0.8 * 6.5 - 3.25 = 2.95; alpha * delta = 0.295.
        let mut q = hand_q();
        let before = q.params().to_vec();
        let sample = HAND_SAMPLE;
        assert!(close(q.q(sample.obs, sample.actions).unwrap(), 3.25));
        assert!(close(q.value(sample.next_obs).unwrap(), 6.5));
        let delta = q.update(Update::Corrected, &sample, 0.8, 0.1).unwrap();
        assert!(close(delta, 2.95), "delta {delta}");
        let mut expected = before.clone();
        expected[0][1] = 2.0 + 0.295 * 0.75;
        expected[0][3] = 4.0 + 0.295 * 0.25;
        expected[1][2] = 2.0 + 0.295 * 0.5;
        expected[1][5] = -0.5 + 0.295 * 0.5;
        for (got, want) in q.params().iter().flatten().zip(expected.iter().flatten()) {
            assert!(close(*got, *want), "{:?} vs {expected:?}", q.params());
        }
        assert!(close(q.params()[0][1], 2.22125));

        // Terminal: no bootstrap, delta = 1 - 3.25.
        let mut q = hand_q();
        let delta = q
            .update(
                Update::Corrected,
                &Sample {
                    terminal: true,
                    ..sample
                },
                0.8,
                0.1,
            )
            .unwrap();
        assert!(close(delta, -2.25));
        assert!(close(q.params()[0][1], 2.0 - 0.225 * 0.75));
        assert!(close(q.params()[1][5], -0.5 - 0.225 * 0.5));
        assert!(close(q.params()[0][0], 1.0));
    }

    #[test]
    fn literal_update_by_hand_gives_every_updated_parameter_the_same_increment() {
        // Gamma = Q(x_{k+1}, (1, 2)) = 5 + (-0.5) = 4.5; beta = 0.8 * 6.5 = 5.2;
        // bracket = 1 + 5.2 - 4.5 = 1.7; Omega = 2 (two agents); increment 0.1 * 1.7 * 2 = 0.34
        // on the taken actions at the cores active at x_{k+1}: agent 0 cores 1, 2 (action 1),
        // agent 1 core 1 (action 2).
        let mut q = hand_q();
        let before = q.params().to_vec();
        let sample = HAND_SAMPLE;
        let bracket = q.update(Update::Literal, &sample, 0.8, 0.1).unwrap();
        assert!(close(bracket, 1.7), "bracket {bracket}");
        let updated = [(0usize, 3usize), (0, 5), (1, 5)];
        for (i, (new, old)) in q.params().iter().zip(&before).enumerate() {
            for (k, (a, b)) in new.iter().zip(old).enumerate() {
                if updated.contains(&(i, k)) {
                    assert!(close(a - b, 0.34), "phi[{i}][{k}]: increment {}", a - b);
                } else {
                    assert_eq!(a, b, "phi[{i}][{k}] must not change");
                }
            }
        }
        // The corrected update of the same sample weighs by membership: unequal increments.
        let mut c = hand_q();
        c.update(Update::Corrected, &sample, 0.8, 0.1).unwrap();
        assert!(!close(c.params()[0][1] - 2.0, c.params()[0][3] - 4.0));
    }

    #[test]
    fn greedy_breaks_ties_by_the_lowest_index_and_serde_round_trips() {
        let features = FeatureSpace::new(vec![vec![vec![0.0, 1.0]]]).unwrap();
        let q = AdditiveQ::from_params(features, vec![3], vec![vec![0.0, 1.0, 1.0, 2.0, 2.0, 0.0]])
            .unwrap();
        assert_eq!(q.greedy(0, &[0.0]).unwrap(), 1);
        assert_eq!(q.greedy(0, &[1.0]).unwrap(), 0);
        assert_eq!(q.greedy(0, &[0.5]).unwrap(), 1); // values (1, 1.5, 0.5)
        let text = toml::to_string(&q).unwrap();
        let back: AdditiveQ = toml::from_str(&text).unwrap();
        assert_eq!(back, q);
        let bad_cores =
            "features = [[[1.0, 0.0]]]\nactions = [3]\nphi = [[0.0, 0.0, 0.0, 0.0, 0.0, 0.0]]";
        assert!(toml::from_str::<AdditiveQ>(bad_cores).is_err());
        let bad_shape = "features = [[[0.0, 1.0]]]\nactions = [3]\nphi = [[0.0]]";
        assert!(toml::from_str::<AdditiveQ>(bad_shape).is_err());
    }

    #[test]
    fn bad_shapes_are_errors() {
        // Bad shapes through the Q-function API.
        let q = hand_q();
        let mut out = [0.0; 2];
        assert!(q.q_agent(0, &[0.5, 1.0], &mut out).is_err());
        assert!(q.q_agent(0, &[f64::NAN], &mut out).is_err());
        assert!(q.q_agent(2, &[0.5], &mut out).is_err());
        assert!(q.q_agent(0, &[0.5], &mut [0.0; 3]).is_err());
        q.q_agent(0, &[0.5], &mut out).unwrap();
        assert_eq!(out, [2.0, 3.0]);
        assert!(q.q(&[&[0.5], &[0.5]], &[2, 0]).is_err());
        assert!(
            AdditiveQ::from_params(q.features().clone(), vec![2, 3], vec![vec![0.0; 6]]).is_err()
        );
        assert!(
            AdditiveQ::from_params(
                q.features().clone(),
                vec![2, 3],
                vec![vec![0.0; 6], vec![f64::NAN; 6]]
            )
            .is_err()
        );
    }
}
