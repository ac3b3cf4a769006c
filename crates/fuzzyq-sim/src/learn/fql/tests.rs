//! Tests of the parent module.

use std::ops::ControlFlow;

use super::*;

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12
}
use crate::learn::codebook::Codebook;

const STEP: f64 = 0.1;
const GOAL: f64 = 0.95;

/// `n` agents, each on its own line `[0, 1]`: actions left, stay, right by [`STEP`]. The
/// joint reward 1 (terminal) comes when every agent is at `>= GOAL`. Starts are uniform in
/// `[0, 0.9)` per agent unless fixed.
struct Lines {
    pos: Vec<f64>,
    fixed_start: Option<Vec<f64>>,
}

impl Lines {
    fn new(n: usize) -> Self {
        Self {
            pos: vec![0.0; n],
            fixed_start: None,
        }
    }
}

impl Environment for Lines {
    fn n_agents(&self) -> usize {
        self.pos.len()
    }
    fn n_actions(&self, _: usize) -> usize {
        3
    }
    fn obs_dim(&self, _: usize) -> usize {
        1
    }
    fn reset(&mut self, rng: &mut Pcg64Mcg) {
        match &self.fixed_start {
            Some(s) => self.pos.clone_from(s),
            None => {
                for p in &mut self.pos {
                    *p = rng.random_range(0.0..0.9);
                }
            }
        }
    }
    fn observe(&self, agent: usize, out: &mut [f64]) {
        out[0] = self.pos[agent];
    }
    fn step(&mut self, actions: &[usize], _: &mut Pcg64Mcg) -> Transition {
        for (p, &a) in self.pos.iter_mut().zip(actions) {
            *p = (*p + STEP * (a as f64 - 1.0)).clamp(0.0, 1.0);
        }
        let done = self.pos.iter().all(|&p| p >= GOAL);
        Transition {
            reward: if done { 1.0 } else { 0.0 },
            terminal: done,
        }
    }
}

fn uniform_cores(k: usize) -> Vec<f64> {
    (0..k).map(|j| j as f64 / (k - 1) as f64).collect()
}

fn continue_all(_: &EpisodeRecord) -> ControlFlow<()> {
    ControlFlow::Continue(())
}

/// Runs the greedy policy of `q` from `start`; the number of steps to the goal, if reached.
fn greedy_steps(q: &AdditiveQ, start: &[f64], limit: usize) -> Option<usize> {
    let mut env = Lines::new(start.len());
    env.pos = start.to_vec();
    let mut rng = Pcg64Mcg::seed_from_u64(0);
    let mut actions = vec![0; start.len()];
    for k in 1..=limit {
        let obs: Vec<[f64; 1]> = env.pos.iter().map(|&p| [p]).collect();
        let obs: Vec<&[f64]> = obs.iter().map(|o| &o[..]).collect();
        q.greedy_joint(&obs, &mut actions).unwrap();
        if env.step(&actions, &mut rng).terminal {
            return Some(k);
        }
    }
    None
}

/// Optimal values of the 1-agent line by value iteration on the lattice `j / 1000`, which
/// the dynamics map to itself (steps of 100 lattice points).
fn line_values(gamma: f64) -> Vec<f64> {
    let n = 1001;
    let goal = 950;
    let mut v = vec![0.0; n];
    loop {
        let mut change: f64 = 0.0;
        for j in 0..n {
            let mut best = f64::NEG_INFINITY;
            for a in [-100i64, 0, 100] {
                let next = (j as i64 + a).clamp(0, n as i64 - 1) as usize;
                let value = if next >= goal { 1.0 } else { gamma * v[next] };
                best = best.max(value);
            }
            change = change.max((best - v[j]).abs());
            v[j] = best;
        }
        if change < 1e-12 {
            return v;
        }
    }
}

fn line_config() -> FqlConfig {
    FqlConfig {
        gamma: 0.9,
        episodes: 600,
        max_steps: 40,
        alpha: 0.2,
        alpha_decay: 200.0,
        epsilon: 1.0,
        epsilon_min: 0.05,
        epsilon_decay_episodes: 400,
        seed: 7,
        tolerance: 1e-6,
        window: 20,
        stop_at_convergence: false,
        eval_every: 25,
        eval_episodes: 20,
        ..FqlConfig::default()
    }
}

#[test]
fn corridor_learns_to_reach_the_goal_with_near_optimal_values() {
    let features = FeatureSpace::new(vec![vec![uniform_cores(11)]]).unwrap();
    let config = line_config();
    let mut env = Lines::new(1);
    let out = learn(&mut env, &features, &config, continue_all).unwrap();
    assert_eq!(out.stop, StopReason::EpisodeLimit);
    assert_eq!(out.curve.len(), config.episodes);
    assert_eq!(
        out.steps_total,
        out.curve.iter().map(|r| r.steps).sum::<usize>()
    );

    // Greedy from every start reaches the goal in (nearly) the optimal number of steps.
    for j in 0..=90 {
        let start = j as f64 / 100.0;
        let optimal = ((GOAL - start) / STEP).ceil() as usize;
        let steps = greedy_steps(&out.q, &[start], 30);
        assert!(
            steps.is_some_and(|s| s <= optimal + 1),
            "start {start}: {steps:?} steps, optimal {optimal}"
        );
    }

    // Values at the cores against value iteration (within 10%).
    let v = line_values(config.gamma);
    for core in [1usize, 3, 5, 7, 9] {
        let x = core as f64 / 10.0;
        let learned = out.q.value(&[&[x]]).unwrap();
        let truth = v[core * 100];
        assert!(
            (learned - truth).abs() <= 0.1 * truth,
            "core {x}: learned {learned}, value iteration {truth}"
        );
    }

    // The learning curve's greedy evaluations reach full success and end there.
    let evals: Vec<f64> = out
        .curve
        .iter()
        .filter_map(|r| r.eval_success_rate)
        .collect();
    assert_eq!(evals.len(), config.episodes / config.eval_every);
    // The untrained greedy policy (phi = 0: lowest index, always left) never succeeds.
    let untrained = AdditiveQ::new(features.clone(), vec![3]).unwrap();
    let before = evaluate(&mut env, &untrained, 20, 40, eval_seed(config.seed)).unwrap();
    assert_eq!(before.success_rate, 0.0);
    let after = evaluate(&mut env, &out.q, 20, 40, eval_seed(config.seed)).unwrap();
    assert_eq!(after.success_rate, 1.0);
    assert_eq!(
        Some(after.mean_return),
        out.curve.last().unwrap().eval_mean_return
    );
    assert_eq!(evals.last(), Some(&1.0));
    let last = out.curve.last().unwrap();
    assert!(last.eval_mean_return.unwrap() > 0.99);
    assert!(last.param_change.is_finite());
    assert!(
        out.curve[..config.window - 1]
            .iter()
            .all(|r| r.param_change.is_nan())
    );
}

#[test]
fn two_agents_learn_to_reach_the_goal_together() {
    let cores = uniform_cores(6);
    let features = FeatureSpace::new(vec![vec![cores.clone()], vec![cores]]).unwrap();
    let config = FqlConfig {
        episodes: 1000,
        max_steps: 60,
        epsilon_decay_episodes: 700,
        seed: 11,
        ..line_config()
    };
    let mut env = Lines::new(2);
    let out = learn(&mut env, &features, &config, continue_all).unwrap();
    assert_eq!(out.q.params().len(), 2);
    assert_eq!(out.q.params()[0].len(), 6 * 3);
    assert_eq!(features.n_params(&[3, 3]).unwrap(), 36);

    for a in [0.0, 0.13, 0.42, 0.77, 0.9] {
        for b in [0.0, 0.31, 0.5, 0.88] {
            let steps = greedy_steps(&out.q, &[a, b], 30);
            assert!(
                steps.is_some_and(|s| s <= 11),
                "start ({a}, {b}): {steps:?}"
            );
        }
    }
    assert_eq!(out.curve.last().unwrap().eval_success_rate, Some(1.0));
}

fn params_bits(q: &AdditiveQ) -> Vec<Vec<u64>> {
    q.params()
        .iter()
        .map(|t| t.iter().map(|v| v.to_bits()).collect())
        .collect()
}

fn csv(curve: &[EpisodeRecord]) -> String {
    let mut buf = Vec::new();
    write_curve_csv(curve, &mut buf).unwrap();
    String::from_utf8(buf).unwrap()
}

#[test]
fn same_seed_is_bit_identical_and_other_seeds_differ() {
    let cores = uniform_cores(6);
    let features = FeatureSpace::new(vec![vec![cores.clone()], vec![cores]]).unwrap();
    let config = FqlConfig {
        episodes: 120,
        eval_every: 30,
        ..line_config()
    };
    let run =
        |config: &FqlConfig| learn(&mut Lines::new(2), &features, config, continue_all).unwrap();
    let a = run(&config);
    let b = run(&config);
    assert_eq!(params_bits(&a.q), params_bits(&b.q));
    assert_eq!(csv(&a.curve), csv(&b.curve));
    assert_eq!(a.steps_total, b.steps_total);
    let c = run(&FqlConfig {
        seed: config.seed + 1,
        ..config.clone()
    });
    assert_ne!(params_bits(&a.q), params_bits(&c.q));
    assert_ne!(csv(&a.curve), csv(&c.curve));
}

/// One agent, one state (on a core), two actions: reward = action index, then terminal.
struct Bandit {
    reward_scale: f64,
}

impl Environment for Bandit {
    fn n_agents(&self) -> usize {
        1
    }
    fn n_actions(&self, _: usize) -> usize {
        2
    }
    fn obs_dim(&self, _: usize) -> usize {
        1
    }
    fn reset(&mut self, _: &mut Pcg64Mcg) {}
    fn observe(&self, _: usize, out: &mut [f64]) {
        out[0] = 0.0;
    }
    fn step(&mut self, actions: &[usize], _: &mut Pcg64Mcg) -> Transition {
        Transition {
            reward: self.reward_scale * actions[0] as f64,
            terminal: true,
        }
    }
}

#[test]
fn windowed_convergence_stops_the_run_but_not_vacuously() {
    let features = FeatureSpace::new(vec![vec![vec![0.0, 1.0]]]).unwrap();
    let config = FqlConfig {
        episodes: 2000,
        alpha: 0.5,
        epsilon: 0.5,
        epsilon_min: 0.5,
        tolerance: 1e-6,
        window: 5,
        eval_every: 0,
        ..FqlConfig::default()
    };
    let out = learn(
        &mut Bandit { reward_scale: 1.0 },
        &features,
        &config,
        continue_all,
    )
    .unwrap();
    assert_eq!(out.stop, StopReason::Converged);
    let k = out.converged_at.unwrap();
    assert_eq!(out.curve.len(), k + 1);
    assert!(out.curve[k].param_change <= 1e-6);
    assert!(out.curve[k - 1].param_change > 1e-6 || out.curve[k - 1].param_change.is_nan());
    assert!((out.q.params()[0][1] - 1.0).abs() < 1e-5);
    assert!(out.q.params()[0][0].abs() < 1e-12);
    // Nothing evaluated when eval_every = 0.
    assert!(out.curve.iter().all(|r| r.eval_success_rate.is_none()));

    // No reward ever: phi stays 0, which must not count as convergence.
    let out = learn(
        &mut Bandit { reward_scale: 0.0 },
        &features,
        &FqlConfig {
            episodes: 50,
            ..config
        },
        continue_all,
    )
    .unwrap();
    assert_eq!(out.stop, StopReason::EpisodeLimit);
    assert_eq!(out.converged_at, None);
    assert_eq!(out.curve.len(), 50);
    assert_eq!(out.curve[10].param_change, 0.0);
}

#[test]
fn callback_stops_early_and_csv_has_one_row_per_episode() {
    let features = FeatureSpace::new(vec![vec![uniform_cores(5)]]).unwrap();
    let config = FqlConfig {
        eval_every: 2,
        ..line_config()
    };
    let mut seen = 0;
    let out = learn(
        &mut Lines::new(1),
        &features,
        &config,
        |r: &EpisodeRecord| {
            seen += 1;
            if r.episode == 3 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        },
    )
    .unwrap();
    assert_eq!(seen, 4);
    assert_eq!(out.stop, StopReason::Callback);
    assert_eq!(out.curve.len(), 4);
    let text = csv(&out.curve);
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 5);
    assert!(lines[0].starts_with("episode,steps,return,"));
    assert_eq!(lines[1].split(',').count(), 12);
    // Episode 0: no evaluation, no full window: empty fields.
    assert!(lines[1].ends_with(",,"), "{}", lines[1]);
    assert!(!lines[2].ends_with(",,"), "{}", lines[2]);
}

#[test]
fn literal_ablation_runs_and_keeps_parameters_finite() {
    let features = FeatureSpace::new(vec![vec![uniform_cores(11)]]).unwrap();
    let config = FqlConfig {
        update: Update::Literal,
        episodes: 200,
        ..line_config()
    };
    let out = learn(&mut Lines::new(1), &features, &config, continue_all).unwrap();
    assert!(out.q.params().iter().flatten().all(|v| v.is_finite()));
    assert!(!out.curve.is_empty());
}

#[test]
fn schedules() {
    let c = FqlConfig {
        alpha: 0.5,
        alpha_decay: 10.0,
        epsilon: 0.9,
        epsilon_min: 0.1,
        epsilon_decay_episodes: 4,
        ..FqlConfig::default()
    };
    assert_eq!(c.alpha_at(0), 0.5);
    assert!(close(c.alpha_at(10), 0.25));
    assert!(close(c.epsilon_at(2), 0.5));
    assert_eq!(c.epsilon_at(4), 0.1);
    assert_eq!(c.epsilon_at(100), 0.1);
    let constant = FqlConfig {
        alpha_decay: f64::INFINITY,
        epsilon_decay_episodes: 0,
        ..c
    };
    assert_eq!(constant.alpha_at(1000), 0.5);
    assert_eq!(constant.epsilon_at(1000), 0.9);
}

fn err_text<T: fmt::Debug>(r: Result<T, SimError>) -> String {
    r.expect_err("expected an error").to_string()
}

#[test]
fn bad_configs_name_the_field() {
    let cases: Vec<(&str, FqlConfig)> = vec![
        (
            "fql.gamma",
            FqlConfig {
                gamma: 1.0,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.gamma",
            FqlConfig {
                gamma: f64::NAN,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.alpha",
            FqlConfig {
                alpha: 0.0,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.alpha",
            FqlConfig {
                alpha: 1.5,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.alpha_decay",
            FqlConfig {
                alpha_decay: -1.0,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.epsilon",
            FqlConfig {
                epsilon: 1.5,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.epsilon_min",
            FqlConfig {
                epsilon: 0.1,
                epsilon_min: 0.2,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.episodes",
            FqlConfig {
                episodes: 0,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.max_steps",
            FqlConfig {
                max_steps: 0,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.tolerance",
            FqlConfig {
                tolerance: f64::INFINITY,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.window",
            FqlConfig {
                window: 0,
                ..FqlConfig::default()
            },
        ),
        (
            "fql.eval_episodes",
            FqlConfig {
                eval_every: 5,
                eval_episodes: 0,
                ..FqlConfig::default()
            },
        ),
    ];
    let features = FeatureSpace::new(vec![vec![uniform_cores(5)]]).unwrap();
    for (field, config) in cases {
        let text = err_text(learn(&mut Lines::new(1), &features, &config, continue_all));
        assert!(text.starts_with(&format!("{field}:")), "{field}: {text}");
    }
    assert!(FqlConfig::default().validate().is_ok());

    // Unknown fields are rejected; missing ones default.
    let parsed: FqlConfig = toml::from_str("update = \"literal\"\ngamma = 0.5").unwrap();
    assert_eq!(parsed.update, Update::Literal);
    assert_eq!(parsed.episodes, FqlConfig::default().episodes);
    assert!(toml::from_str::<FqlConfig>("gama = 0.5").is_err());
}

/// Observes NaN for agent 1.
struct NanObs(Lines);

impl Environment for NanObs {
    fn n_agents(&self) -> usize {
        self.0.n_agents()
    }
    fn n_actions(&self, a: usize) -> usize {
        self.0.n_actions(a)
    }
    fn obs_dim(&self, a: usize) -> usize {
        self.0.obs_dim(a)
    }
    fn reset(&mut self, rng: &mut Pcg64Mcg) {
        self.0.reset(rng);
    }
    fn observe(&self, agent: usize, out: &mut [f64]) {
        self.0.observe(agent, out);
        if agent == 1 {
            out[0] = f64::NAN;
        }
    }
    fn step(&mut self, actions: &[usize], rng: &mut Pcg64Mcg) -> Transition {
        self.0.step(actions, rng)
    }
}

#[test]
fn mismatched_or_bad_environments_are_errors() {
    let one = FeatureSpace::new(vec![vec![uniform_cores(5)]]).unwrap();
    let two = FeatureSpace::new(vec![vec![uniform_cores(5)], vec![uniform_cores(5)]]).unwrap();
    let config = FqlConfig::default();
    let text = err_text(learn(&mut Lines::new(2), &one, &config, continue_all));
    assert!(
        text.starts_with("features:") && text.contains("1 agents"),
        "{text}"
    );
    let wide = FeatureSpace::new(vec![vec![uniform_cores(5), uniform_cores(3)]]).unwrap();
    let text = err_text(learn(&mut Lines::new(1), &wide, &config, continue_all));
    assert!(
        text.starts_with("features[0]:") && text.contains("observation dimensions"),
        "{text}"
    );
    let text = err_text(learn(
        &mut NanObs(Lines::new(2)),
        &two,
        &config,
        continue_all,
    ));
    assert!(
        text.contains("agent 1") && text.contains("non-finite"),
        "{text}"
    );

    // Invalid feature spaces name the agent.
    let text = err_text(FeatureSpace::new(vec![
        vec![uniform_cores(3)],
        vec![vec![0.0, 0.0]],
    ]));
    assert!(text.starts_with("features[1]:"), "{text}");
    assert!(FeatureSpace::new(vec![]).is_err());
    assert!(FeatureSpace::new(vec![vec![]]).is_err());
}

fn two_cell_features() -> FeatureSpace {
    FeatureSpace::codebook(vec![
        Codebook::new(vec![vec![0.0], vec![1.0]], vec![1.0]).unwrap(),
        Codebook::new(
            vec![vec![0.0, 0.0], vec![1.0, 0.0], vec![0.0, 2.0]],
            vec![1.0, 2.0],
        )
        .unwrap(),
    ])
    .unwrap()
}

#[test]
fn codebook_features_are_crisp_cells_and_serialise_in_their_own_form() {
    let features = two_cell_features();
    assert!(features.is_codebook());
    assert!(features.cores().is_empty());
    assert_eq!(features.codebooks().len(), 2);
    assert_eq!(features.n_agents(), 2);
    assert_eq!(
        (features.obs_dim(1), features.n_cores(1)),
        (Some(2), Some(3))
    );
    assert_eq!(features.n_params(&[2, 4]).unwrap(), 2 * 2 + 3 * 4);
    assert!(features.grid(0).is_err());
    let mut seen = Vec::new();
    features
        .active(1, &[0.2, 1.5])
        .unwrap()
        .for_each(|d, w| seen.push((d, w)));
    assert_eq!(seen, [(2, 1.0)]);
    assert!(features.active(1, &[0.2]).is_err());
    assert!(features.active(0, &[f64::INFINITY]).is_err());
    assert!(features.active(2, &[0.0]).is_err());
    let fuzzy = FeatureSpace::new(vec![vec![uniform_cores(3)]]).unwrap();
    assert!(!fuzzy.is_codebook() && fuzzy.codebooks().is_empty());

    // Round trip through TOML, inside an AdditiveQ.
    let phi = vec![vec![0.5, -1.0, 2.0, 0.25], (0..12).map(f64::from).collect()];
    let q = AdditiveQ::from_params(features.clone(), vec![2, 4], phi).unwrap();
    let text = toml::to_string(&q).unwrap();
    assert!(text.contains("codebooks"), "{text}");
    let back: AdditiveQ = toml::from_str(&text).unwrap();
    assert_eq!(back, q);
    assert_eq!(
        toml::from_str::<FeatureSpace>(&toml::to_string(&features).unwrap()).unwrap(),
        features
    );
    // The fuzzy form is still the nested core lists.
    let text = toml::to_string(&AdditiveQ::new(fuzzy, vec![1]).unwrap()).unwrap();
    assert!(text.starts_with("features = [[[0.0, 0.5, 1.0]]]"), "{text}");
    // Bad codebook files are refused with the reason.
    let bad = "actions = [1]\nphi = [[0.0]]\n[features]\ncodebooks = [{ scale = [0.0], centroids = [[1.0]] }]";
    let e = toml::from_str::<AdditiveQ>(bad).unwrap_err().to_string();
    assert!(e.contains("codebook.scale"), "{e}");
    let unknown = "actions = [1]\nphi = [[0.0]]\n[features]\ncodebook = []";
    let e = toml::from_str::<AdditiveQ>(unknown)
        .unwrap_err()
        .to_string();
    assert!(e.contains("codebook"), "{e}");
    let good = "actions = [1]\nphi = [[0.0, 3.0]]\n[features]\ncodebooks = [{ scale = [1.0], centroids = [[1.0], [2.0]] }]";
    let q = toml::from_str::<AdditiveQ>(good).unwrap();
    assert_eq!(q.greedy(0, &[1.9]).unwrap(), 0);
    assert_eq!(q.value(&[&[1.9]]).unwrap(), 3.0);
    let mixed = "actions = [1]\nphi = [[0.0, 0.0]]\n[features]\ncodebooks = [{ scale = [1.0], centroids = [[1.0], [1.0, 2.0]] }]";
    assert!(toml::from_str::<AdditiveQ>(mixed).is_err());
    assert!(toml::from_str::<AdditiveQ>("features = 3\nactions = [1]\nphi = [[0.0]]").is_err());
}

#[test]
fn codebook_update_is_tabular_q_learning() {
    // One cell of membership 1 per agent: Q(x, u) = phi0[c0 * 2 + u0] + phi1[c1 * 4 + u1].
    let features = two_cell_features();
    let phi = vec![vec![0.5, -1.0, 2.0, 0.25], (0..12).map(f64::from).collect()];
    let mut q = AdditiveQ::from_params(features, vec![2, 4], phi).unwrap();
    let before = q.params().to_vec();
    // x_k: agent 0 in cell 1 (0.8), agent 1 in cell 0 ((0.1, 0.5): scaled distances 0.0725
    // to (0, 0), 0.8725 to (1, 0) and 0.5725 to (0, 2)); actions (1, 3): Q = 0.25 + 3.
    // x_{k+1}: cell 0 (max 0.5) and cell 2 (max 11): max Q = 11.5.
    let sample = Sample {
        obs: &[&[0.8], &[0.1, 0.5]],
        actions: &[1, 3],
        reward: 2.0,
        next_obs: &[&[-0.3], &[0.0, 1.9]],
        terminal: false,
    };
    let delta = q.update(Update::Corrected, &sample, 0.9, 0.5).unwrap();
    assert!(close(delta, 2.0 + 0.9 * 11.5 - 3.25), "delta {delta}");
    let mut expected = before.clone();
    expected[0][3] += 0.5 * delta;
    expected[1][3] += 0.5 * delta;
    assert_eq!(q.params(), &expected[..]);

    // Learning the corridor over an 11-cell codebook (the cores of the fuzzy test, crisp).
    let cells: Vec<Vec<f64>> = uniform_cores(11).into_iter().map(|c| vec![c]).collect();
    let features = FeatureSpace::codebook(vec![Codebook::new(cells, vec![1.0]).unwrap()]).unwrap();
    let config = line_config();
    let out = learn(&mut Lines::new(1), &features, &config, continue_all).unwrap();
    for j in 0..=90 {
        let start = j as f64 / 100.0;
        let optimal = ((GOAL - start) / STEP).ceil() as usize;
        let steps = greedy_steps(&out.q, &[start], 30);
        assert!(
            steps.is_some_and(|s| s <= optimal + 2),
            "start {start}: {steps:?}"
        );
    }
    assert_eq!(out.curve.last().unwrap().eval_success_rate, Some(1.0));
    let again = learn(&mut Lines::new(1), &features, &config, continue_all).unwrap();
    assert_eq!(params_bits(&again.q), params_bits(&out.q));
    let eval = evaluate(&mut Lines::new(1), &out.q, 20, 40, eval_seed(config.seed)).unwrap();
    assert_eq!(eval.success_rate, 1.0);
}

/// [`Lines`] cut by the environment after `limit` steps (a time limit of its own).
struct Cut {
    lines: Lines,
    limit: usize,
    steps: usize,
}

impl Environment for Cut {
    fn n_agents(&self) -> usize {
        self.lines.n_agents()
    }
    fn n_actions(&self, a: usize) -> usize {
        self.lines.n_actions(a)
    }
    fn obs_dim(&self, a: usize) -> usize {
        self.lines.obs_dim(a)
    }
    fn reset(&mut self, rng: &mut Pcg64Mcg) {
        self.steps = 0;
        self.lines.reset(rng);
    }
    fn observe(&self, agent: usize, out: &mut [f64]) {
        self.lines.observe(agent, out);
    }
    fn step(&mut self, actions: &[usize], rng: &mut Pcg64Mcg) -> Transition {
        self.steps += 1;
        self.lines.step(actions, rng)
    }
    fn truncated(&self) -> bool {
        self.steps >= self.limit
    }
}

#[test]
fn an_environment_that_cuts_its_episodes_ends_them_there() {
    let features = FeatureSpace::new(vec![vec![uniform_cores(11)]]).unwrap();
    let config = FqlConfig {
        episodes: 40,
        ..line_config()
    };
    let mut env = Cut {
        lines: Lines::new(1),
        limit: 5,
        steps: 0,
    };
    let outcome = learn(&mut env, &features, &config, continue_all).unwrap();
    assert!(outcome.curve.iter().all(|r| r.steps <= 5));
    assert!(outcome.curve.iter().any(|r| r.steps == 5 && !r.terminal));
    assert_eq!(
        outcome.steps_total,
        outcome.curve.iter().map(|r| r.steps).sum::<usize>()
    );
    // Uncut, the same runs last up to the learner's own limit.
    let uncut = learn(&mut Lines::new(1), &features, &config, continue_all).unwrap();
    assert!(uncut.curve.iter().any(|r| r.steps > 5));
}

#[test]
fn vqql_quantises_any_environment() {
    let mut env = Cut {
        lines: Lines::new(2),
        limit: 10,
        steps: 0,
    };
    let config = crate::learn::vqql::VqqlConfig {
        cells: 6,
        samples: 400,
        explore_steps: 50,
        ..Default::default()
    };
    let (features, report) = crate::learn::vqql::build_codebook_on(&mut env, &config).unwrap();
    assert!(features.is_codebook());
    assert_eq!(
        (features.n_cores(0), features.n_cores(1)),
        (Some(6), Some(6))
    );
    assert_eq!(report.agents.len(), 2);
    let again = crate::learn::vqql::build_codebook_on(&mut env, &config).unwrap();
    assert_eq!(again.0, features);
    // Exactly `samples` observations per agent, one value each.
    let mut rng = Pcg64Mcg::seed_from_u64(3);
    let samples = crate::learn::vqql::explore_env(&mut env, 33, 50, &mut rng).unwrap();
    assert_eq!(samples.len(), 2);
    assert_eq!(samples[0].len(), 33);
    let outcome = learn(&mut env, &features, &line_config(), continue_all).unwrap();
    assert!(outcome.q.phi.iter().flatten().all(|v| v.is_finite()));
}
