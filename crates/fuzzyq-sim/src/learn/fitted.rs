//! Fuzzy Q-iteration from samples: batch, model-free fitted Q-iteration with the fuzzy
//! approximator (Ernst, Geurts and Wehenkel 2005), which is an averager (Gordon 1995).
//!
//! Given transitions `(x_s, u_s, x'_s, r_s)` of a plant ([`Transitions`]), each agent `i`
//! keeps `theta_i[c, a]` over the fuzzy cores `c` of its own observation (its block of the
//! state) and its own actions `a`. Starting from `theta = 0`, one iteration computes, for
//! every agent, the targets
//!
//! `y_s = r_s + gamma * max_a sum_c mu_c(x'_s) theta_i[c, a]`
//!
//! and replaces each parameter by the membership-weighted average of the targets of the
//! samples that took its action:
//!
//! `theta_i[c, a] = sum_{s: u_s = a} mu_c(x_s) y_s / sum_{s: u_s = a} mu_c(x_s)`
//!
//! (a parameter no such sample touches keeps its value). Every new parameter is a weighted
//! average of targets, with weights that are non-negative and sum to 1, so an iteration is a
//! `gamma`-contraction in the maximum norm. It converges from any start to one fixed point,
//! needs no step size and cannot diverge, unlike the sample-by-sample updates of
//! [`fql`](super::fql). It stops when the largest change is at most `xi` (then every
//! parameter is within `gamma xi / (1 - gamma)` of the fixed point) or after
//! `max_iterations`.
//!
//! The agents learn independently: each fits the shared reward from its own observation and
//! actions. The result is an [`AdditiveQ`] whose agent terms are the agents' Q-functions, so
//! each agent acts greedily on its own term (the additive layout's greedy joint action). The
//! sum of the terms is not a return estimate: each term estimates the whole return.
//!
//! The iterations run in a fixed order on one thread: the same transitions give the same
//! parameters, bit for bit.

use fuzzyq_core::partition::ActiveCores;

use crate::error::{ConfigError, SimError, require};
use crate::learn::additive::AdditiveQ;
use crate::learn::features::FeatureSpace;
use crate::learn::samples::Transitions;
use crate::model::ActionTable;

/// How [`fitted_q`] iterates.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FittedConfig {
    /// Discount, in `[0, 1)`.
    pub gamma: f64,
    /// Stop when the largest parameter change of an iteration is at most `xi` (`> 0`).
    pub xi: f64,
    /// Iteration limit, `>= 1`.
    pub max_iterations: usize,
}

impl FittedConfig {
    /// Checks the settings; errors name the field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        require!(
            (0.0..1.0).contains(&self.gamma),
            "gamma",
            format!("must be in [0, 1), got {}", self.gamma),
        );
        require!(
            self.xi > 0.0 && self.xi.is_finite(),
            "xi",
            format!("must be a positive number, got {}", self.xi),
        );
        require!(
            self.max_iterations >= 1,
            "max_iterations",
            "must be at least 1"
        );
        Ok(())
    }
}

/// The result of [`fitted_q`].
#[derive(Clone, Debug)]
pub struct FittedOutcome {
    /// The agents' Q-functions.
    pub q: AdditiveQ,
    /// Iterations performed.
    pub iterations: usize,
    /// Whether the last change was at most `xi`.
    pub converged: bool,
    /// The largest parameter change of the last iteration.
    pub last_change: f64,
}

/// One agent's view of the transitions: the active cores of its observation before and
/// after each transition (flattened, `start[s]..start[s + 1]`), and its action indices.
struct AgentSamples {
    start: Vec<usize>,
    next_start: Vec<usize>,
    index: Vec<u32>,
    weight: Vec<f64>,
    next_index: Vec<u32>,
    next_weight: Vec<f64>,
    action: Vec<u32>,
}

fn push_active(active: &ActiveCores<f64>, index: &mut Vec<u32>, weight: &mut Vec<f64>) {
    active.for_each(|c, w| {
        index.push(c as u32);
        weight.push(w);
    });
}

/// Agent `agent`'s samples: its observation is the state's variables `offset..offset + dim`.
fn agent_samples(
    data: &Transitions,
    features: &FeatureSpace,
    actions: &ActionTable,
    agent: usize,
    offset: usize,
) -> Result<AgentSamples, SimError> {
    let dim = features.obs_dim(agent).unwrap_or(0);
    let a = actions.dim();
    let mut s = AgentSamples {
        start: vec![0],
        next_start: vec![0],
        index: Vec::new(),
        weight: Vec::new(),
        next_index: Vec::new(),
        next_weight: Vec::new(),
        action: Vec::with_capacity(data.len()),
    };
    for k in 0..data.len() {
        let (x, u, next, _) = data.get(k);
        let own = &u[agent * a..(agent + 1) * a];
        let Some(j) = (0..actions.len()).find(|&j| actions.action(j) == own) else {
            return Err(ConfigError::invalid(
                "transitions.actions",
                format!("transition {k}: agent {agent}'s action {own:?} is not one of its actions"),
            )
            .into());
        };
        s.action.push(j as u32);
        let cur = features.active(agent, &x[offset..offset + dim])?;
        push_active(&cur, &mut s.index, &mut s.weight);
        s.start.push(s.index.len());
        let after = features.active(agent, &next[offset..offset + dim])?;
        push_active(&after, &mut s.next_index, &mut s.next_weight);
        s.next_start.push(s.next_index.len());
    }
    Ok(s)
}

/// One iteration for one agent: the new parameters from `theta` into `out` (see the
/// [module docs](self)); returns the largest change.
fn iterate(
    s: &AgentSamples,
    rewards: &[f64],
    m: usize,
    gamma: f64,
    theta: &[f64],
    sums: &mut [(f64, f64)],
    out: &mut [f64],
) -> f64 {
    sums.fill((0.0, 0.0));
    let mut q = vec![0.0; m];
    for (k, &r) in rewards.iter().enumerate() {
        q.fill(0.0);
        for e in s.next_start[k]..s.next_start[k + 1] {
            let (c, w) = (s.next_index[e] as usize, s.next_weight[e]);
            for (qa, t) in q.iter_mut().zip(&theta[c * m..(c + 1) * m]) {
                *qa += w * t;
            }
        }
        let best = q.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let y = r + gamma * best;
        let a = s.action[k] as usize;
        for e in s.start[k]..s.start[k + 1] {
            let (c, w) = (s.index[e] as usize, s.weight[e]);
            let (num, den) = &mut sums[c * m + a];
            *num += w * y;
            *den += w;
        }
    }
    let mut change = 0.0f64;
    for ((o, &t), &(num, den)) in out.iter_mut().zip(theta).zip(sums.iter()) {
        *o = if den > 0.0 { num / den } else { t };
        change = change.max((*o - t).abs());
    }
    change
}

/// Fuzzy Q-iteration from the samples `data` (see the [module docs](self)): agent `i`
/// observes its block of the state (the agents' observation lengths in `features`, in
/// order, make up the state) and takes the actions of `actions`. Errors name what is wrong:
/// no transitions, observation lengths that do not make up the state, an action not in the
/// table, non-finite values.
pub fn fitted_q(
    data: &Transitions,
    features: &FeatureSpace,
    actions: &ActionTable,
    config: &FittedConfig,
) -> Result<FittedOutcome, SimError> {
    config.validate()?;
    require!(!data.is_empty(), "transitions", "need at least one");
    let n = features.n_agents();
    let dims: Vec<usize> = (0..n).map(|i| features.obs_dim(i).unwrap_or(0)).collect();
    require!(
        dims.iter().sum::<usize>() == data.state_dim() && data.action_dim() == n * actions.dim(),
        "transitions",
        format!(
            "states of {} values and actions of {} do not fit {n} agents observing {dims:?} \
             values with actions of {} each",
            data.state_dim(),
            data.action_dim(),
            actions.dim()
        ),
    );
    let rewards: Vec<f64> = (0..data.len()).map(|k| data.get(k).3).collect();
    require!(
        rewards.iter().all(|r| r.is_finite()),
        "transitions.rewards",
        "must be finite numbers",
    );
    let mut offset = 0;
    let mut agents = Vec::with_capacity(n);
    for (i, d) in dims.iter().enumerate() {
        agents.push(agent_samples(data, features, actions, i, offset)?);
        offset += d;
    }
    let m = actions.len();
    let mut theta: Vec<Vec<f64>> = (0..n)
        .map(|i| vec![0.0; features.n_cores(i).unwrap_or(0) * m])
        .collect();
    let mut next = theta.clone();
    let mut sums: Vec<Vec<(f64, f64)>> = theta.iter().map(|t| vec![(0.0, 0.0); t.len()]).collect();
    let (mut iterations, mut change) = (0, f64::INFINITY);
    while iterations < config.max_iterations && change > config.xi {
        change = 0.0;
        for i in 0..n {
            let c = iterate(
                &agents[i],
                &rewards,
                m,
                config.gamma,
                &theta[i],
                &mut sums[i],
                &mut next[i],
            );
            change = change.max(c);
        }
        std::mem::swap(&mut theta, &mut next);
        iterations += 1;
    }
    Ok(FittedOutcome {
        q: AdditiveQ::from_params(features.clone(), vec![m; n], theta)?,
        iterations,
        converged: change <= config.xi,
        last_change: change,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::samples::{Collection, Exploration, collect};
    use crate::learn::tasks::pointmass::feature_space;
    use crate::model::F64Model;
    use crate::model::pointmass::{PointMass, PointMassConfig, Starts};

    use crate::test_support::one_point_mass as one_agent;

    /// One agent with a reward region of radius 0.5, which random actions meet often.
    fn wide_goal() -> PointMass {
        PointMass::new(PointMassConfig {
            agents: 1,
            goal_radius: 0.5,
            ..PointMassConfig::default()
        })
        .unwrap()
    }

    fn data(model: &PointMass, samples: usize, seed: u64) -> Transitions {
        let starts = Starts::Uniform {
            position: 1.0,
            velocity: 0.0,
        };
        let collection = Collection {
            samples,
            episode_steps: 30,
            seed,
        };
        collect(
            model,
            &collection,
            |rng, x| starts.draw(rng, x),
            &mut Exploration::Random,
        )
        .unwrap()
    }

    const CONFIG: FittedConfig = FittedConfig {
        gamma: 0.9,
        xi: 1e-6,
        max_iterations: 2000,
    };

    #[test]
    fn the_fixed_point_is_the_average_of_its_own_targets() {
        let model = wide_goal();
        let features =
            feature_space(&model, &[-1.0, -0.1, 0.0, 0.1, 1.0], &[-1.0, 0.0, 1.0]).unwrap();
        let d = data(&model, 3000, 1);
        let out = fitted_q(&d, &features, model.actions(), &CONFIG).unwrap();
        assert!(out.converged, "{} iterations", out.iterations);
        assert!(
            out.q.params()[0].iter().any(|&p| p > 0.0),
            "the goal was met"
        );
        // Every parameter is within the range of the discounted returns.
        let bound = 5.0 / (1.0 - CONFIG.gamma);
        assert!(out.q.params()[0].iter().all(|p| p.abs() <= bound));
        // At the fixed point one more iteration changes nothing beyond xi's bound.
        let agents = agent_samples(&d, &features, model.actions(), 0, 0).unwrap();
        let rewards: Vec<f64> = (0..d.len()).map(|k| d.get(k).3).collect();
        let theta = &out.q.params()[0];
        let mut again = vec![0.0; theta.len()];
        let mut sums = vec![(0.0, 0.0); theta.len()];
        let change = iterate(&agents, &rewards, 25, 0.9, theta, &mut sums, &mut again);
        assert!(change <= CONFIG.xi, "{change}");
        // Same samples, same parameters, bit for bit.
        let twice = fitted_q(&d, &features, model.actions(), &CONFIG).unwrap();
        assert_eq!(twice.q.params(), out.q.params());
    }

    #[test]
    fn a_greedy_policy_from_samples_alone_reaches_the_goal() {
        // One point mass near the goal, the paper's cores: fitted Q on 20,000 random
        // transitions drives it into the reward region.
        let model = one_agent();
        let features = feature_space(
            &model,
            &crate::paper::POSITION_CORES,
            &crate::paper::VELOCITY_CORES,
        )
        .unwrap();
        let d = data(&model, 20_000, 2);
        let config = FittedConfig {
            gamma: 0.96,
            xi: 0.05,
            max_iterations: 1000,
        };
        let out = fitted_q(&d, &features, model.actions(), &config).unwrap();
        let (t, m) =
            crate::test_support::rollout_additive(&model, &out.q, &[0.8, -0.6, 0.0, 0.0], 60, 0.96)
                .unwrap();
        assert!(m.reach_step.is_some(), "{m:?}");
        assert!(m.final_error_m[0] < 0.15, "{m:?}");
        assert_eq!(t.states.len(), 61);
    }

    #[test]
    fn misfit_samples_name_the_problem() {
        let model = one_agent();
        let features = feature_space(&model, &[-1.0, 0.0, 1.0], &[-1.0, 0.0, 1.0]).unwrap();
        let mut d = data(&model, 10, 3);
        let e = fitted_q(
            &d,
            &features,
            model.actions(),
            &FittedConfig {
                gamma: 1.0,
                ..CONFIG
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("gamma"), "{e}");
        let empty = Transitions::new(4, 2);
        let e = fitted_q(&empty, &features, model.actions(), &CONFIG).unwrap_err();
        assert!(e.to_string().contains("transitions"), "{e}");
        let two = PointMass::paper();
        let e = fitted_q(
            &d,
            &feature_space(&two, &[-1.0, 1.0], &[-1.0, 1.0]).unwrap(),
            two.actions(),
            &CONFIG,
        )
        .unwrap_err();
        assert!(e.to_string().contains("do not fit"), "{e}");
        let (x, _, next, r) = d.get(0);
        let (x, next) = (x.to_vec(), next.to_vec());
        d.push(&x, &[0.5, 0.5], &next, r);
        let e = fitted_q(&d, &features, model.actions(), &CONFIG).unwrap_err();
        assert!(e.to_string().contains("not one of its actions"), "{e}");
    }
}
