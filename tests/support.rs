//! Shared fixtures of the integration tests: small point-mass problems, a brute-force fuzzy
//! Q-iteration that stores the whole `theta`, thread-pool helpers and float comparison.
#![allow(missing_docs)] // test support

use fuzzyq_core::model::joint_actions;
use fuzzyq_core::solver::Grid;
use fuzzyq_core::{Model, ProductPartition, Real};
use fuzzyq_sim::model::pointmass::{PointMass, PointMassConfig};

/// The block-path operator of `m` over `g` with discount `gamma` and no absorbing goal.
pub fn block_operator<'a, T: Real, M: Model<T> + Sync>(
    m: &'a M,
    g: &'a Grid<T>,
    gamma: T,
) -> fuzzyq_core::solver::Operator<'a, T, M> {
    let backup = fuzzyq_core::Backup::discounted(gamma);
    fuzzyq_core::solver::Operator::new(m, g.view(), backup, fuzzyq_core::solver::BackupPath::Block)
        .expect("a block operator")
}

/// Asserts that every run of `runs` gives the first one's values, greedy actions and final
/// change, bit for bit.
#[track_caller]
pub fn assert_same_bits<T: Real>(runs: &[fuzzyq_core::solver::Solution<T>]) {
    for r in &runs[1..] {
        assert!(
            r.v.iter()
                .zip(&runs[0].v)
                .all(|(a, b)| a.to_f64().to_bits() == b.to_f64().to_bits())
        );
        assert_eq!(r.greedy, runs[0].greedy);
        assert_eq!(r.final_delta.to_bits(), runs[0].final_delta.to_bits());
    }
}

/// Asserts `|a - b| <= tol` elementwise, naming the first offending index.
#[track_caller]
pub fn assert_close<T: Real>(a: &[T], b: &[T], tol: f64) {
    assert_eq!(a.len(), b.len(), "lengths differ");
    for (i, (&x, &y)) in a.iter().zip(b).enumerate() {
        let d = (x.to_f64() - y.to_f64()).abs();
        assert!(d <= tol, "index {i}: {x} vs {y} (|diff| {d:e} > {tol:e})");
    }
}

/// Largest absolute difference.
pub fn max_diff<T: Real>(a: &[T], b: &[T]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(&x, &y)| (x.to_f64() - y.to_f64()).abs())
        .fold(0.0, f64::max)
}

/// Runs `f` on a dedicated rayon pool of `n` threads.
pub fn with_threads<R: Send>(n: usize, f: impl FnOnce() -> R + Send) -> R {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .expect("thread pool")
        .install(f)
}

/// A point-mass model with `agents` agents and the paper's parameters otherwise.
/// Friction 1 everywhere but a patch of friction 3 (radius 1.5) around `(-2, -2)`: a
/// position-dependent model.
pub fn friction_patch() -> fuzzyq_sim::model::pointmass::FrictionConfig {
    fuzzyq_sim::model::pointmass::FrictionConfig::Patches {
        base: 1.0,
        patches: vec![fuzzyq_sim::model::pointmass::FrictionPatch {
            center: [-2.0, -2.0],
            radius: 1.5,
            eta: 3.0,
        }],
    }
}

pub fn point_mass(agents: usize) -> PointMass {
    PointMass::new(PointMassConfig {
        agents,
        ..PointMassConfig::default()
    })
    .expect("valid config")
}

/// A point-mass grid with the given position and velocity cores on every agent and axis.
pub fn grid<T: Real>(agents: usize, pos: &[f64], vel: &[f64]) -> Grid<T> {
    let conv = |c: &[f64]| c.iter().map(|&v| T::from_f64(v)).collect::<Vec<T>>();
    let mut cores = Vec::new();
    for _ in 0..agents {
        cores.extend([conv(pos), conv(pos), conv(vel), conv(vel)]);
    }
    Grid::new(cores).expect("valid grid")
}

/// A one-agent problem small enough to store `theta` (225 cores x 25 actions).
pub fn small_one_agent<T: Real>() -> (PointMass, Grid<T>) {
    (
        point_mass(1),
        grid(1, &[-6.0, -1.0, 0.0, 1.0, 6.0], &[-3.0, 0.0, 3.0]),
    )
}

/// A two-agent problem cheap enough for the generic path (1296 cores x 625 joint actions;
/// the origin is a core, so the reward is reachable).
pub fn small_two_agent<T: Real>() -> (PointMass, Grid<T>) {
    (point_mass(2), grid(2, &[-6.0, 0.0, 6.0], &[-3.0, 0.0]))
}

/// A symmetric two-agent problem for the block path (6561 cores x 625 joint actions).
pub fn medium_two_agent<T: Real>() -> (PointMass, Grid<T>) {
    (point_mass(2), grid(2, &[-6.0, 0.0, 6.0], &[-3.0, 0.0, 3.0]))
}

/// The result of the brute-force reference.
pub struct Reference<T> {
    /// `theta_K`, row-major `[core][joint action]`.
    pub theta: Vec<T>,
    /// `theta_{K+1}`: one more sweep, the Q-function a greedy policy derives from `V_K`.
    pub theta_next: Vec<T>,
    /// `||theta_k - theta_{k-1}||_inf` for every sweep.
    pub deltas: Vec<f64>,
}

/// Fuzzy Q-iteration exactly as the paper writes it, storing every Q-value:
/// `theta_{k+1}[d, u] = rho(x_d, u) + gamma sum_d' mu_d'(f(x_d, u)) max_u' theta_k[d', u']`,
/// from `theta_0 = 0`, stopping at the first sweep with `||theta_{k+1} - theta_k|| <= xi`.
/// A terminal successor is worth nothing (`theta[d, u] = rho`), and so is every successor of
/// an absorbing goal core.
pub fn brute_force<T: Real, M: Model<T>>(
    model: &M,
    grid: &Grid<T>,
    gamma: f64,
    xi: f64,
    absorbing_goal: bool,
) -> Reference<T> {
    let g: ProductPartition<'_, T> = grid.view();
    let joint = joint_actions(model).expect("joint actions");
    let (n, m, e) = (g.n_cores(), joint.n_joint(), g.n_dims());
    let gamma = T::from_f64(gamma);
    let (mut x, mut next, mut u) = (
        vec![T::ZERO; e],
        vec![T::ZERO; e],
        vec![T::ZERO; joint.dim()],
    );
    // Per pair: reward and, unless terminal, the successor's memberships.
    type Pair<T> = (T, Option<Vec<(usize, T)>>);
    let mut pairs: Vec<Pair<T>> = Vec::new();
    let mut goal = Vec::new();
    for d in 0..n {
        g.core_state(d, &mut x).unwrap();
        goal.push(absorbing_goal && model.is_goal(&x));
        for a in 0..m {
            joint.vector(a, &mut u).unwrap();
            model.step(&x, &u, &mut next);
            let succ = (!model.is_terminal(&next)).then(|| {
                let mut s = Vec::new();
                g.active(&next).unwrap().for_each(|k, w| s.push((k, w)));
                s
            });
            pairs.push((model.reward(&x, &u), succ));
        }
    }
    let sweep = |theta: &[T]| -> Vec<T> {
        let v: Vec<T> = theta
            .chunks(m)
            .map(|r| r.iter().copied().fold(r[0], T::max_of))
            .collect();
        (0..n * m)
            .map(|i| match (&pairs[i], goal[i / m]) {
                ((r, _), true) | ((r, None), false) => *r,
                ((r, Some(s)), false) => {
                    let mut ev = T::ZERO;
                    for &(k, w) in s {
                        ev += w * v[k];
                    }
                    *r + gamma * ev
                }
            })
            .collect()
    };
    let mut theta = vec![T::ZERO; n * m];
    let mut deltas = Vec::new();
    loop {
        let new = sweep(&theta);
        deltas.push(max_diff(&new, &theta));
        theta = new;
        if *deltas.last().unwrap() <= xi || deltas.len() >= 10_000 {
            break;
        }
    }
    Reference {
        theta_next: sweep(&theta),
        theta,
        deltas,
    }
}

/// `V[d] = max_u theta[d, u]` and the lowest-index argmax of each row.
pub fn max_and_argmax<T: Real>(theta: &[T], m: usize) -> (Vec<T>, Vec<u32>) {
    theta
        .chunks(m)
        .map(|row| {
            let a = fuzzyq_core::q::argmax(row).expect("non-empty row");
            (row[a], a as u32)
        })
        .unzip()
}

/// A fuzzy Q-iteration policy of a training result.
pub fn fqi_policy(a: fuzzyq_sim::PolicyArtifact) -> fuzzyq_sim::run::policy::Policy {
    fuzzyq_sim::run::policy::Policy::Fqi(
        fuzzyq_sim::run::policy::FqiPolicy::from_artifact(a).expect("a valid policy"),
    )
}

/// One point-mass run of `policy` on the model.
pub fn point_mass_run(
    policy: &fuzzyq_sim::run::policy::Policy,
    x0: &[f64],
    steps: usize,
    kind: fuzzyq_core::q::PolicyKind,
) -> Result<
    (
        fuzzyq_sim::run::metrics::Trajectory,
        fuzzyq_sim::run::metrics::RolloutMetrics,
    ),
    fuzzyq_sim::SimError,
> {
    use fuzzyq_sim::run::evaluate::{Outcome, PlantChoice, RolloutSpec, run};
    let spec = RolloutSpec {
        kind,
        steps,
        plant: PlantChoice::Model,
        seed: 0,
    };
    match run(policy, x0, &spec)? {
        Outcome::PointMass {
            trajectory,
            metrics,
            ..
        } => Ok((trajectory, metrics)),
        other => panic!("not a point-mass run: {other:?}"),
    }
}

/// One run of a robot `policy` from poses `start` on the plant seeded with `seed`.
pub fn khepera_run(
    policy: &fuzzyq_sim::run::policy::Policy,
    start: &[[f64; 3]],
    steps: usize,
    kind: fuzzyq_core::q::PolicyKind,
    seed: u64,
) -> Result<
    (
        fuzzyq_sim::run::metrics::KheperaRun,
        fuzzyq_sim::run::metrics::KheperaMetrics,
    ),
    fuzzyq_sim::SimError,
> {
    use fuzzyq_sim::run::evaluate::{Outcome, PlantChoice, RolloutSpec, run};
    let flat: Vec<f64> = start.iter().flatten().copied().collect();
    let spec = RolloutSpec {
        kind,
        steps,
        plant: PlantChoice::Model,
        seed,
    };
    match run(policy, &flat, &spec)? {
        Outcome::Khepera { run, metrics } => Ok((run, metrics)),
        other => panic!("not a robot run: {other:?}"),
    }
}

/// Model `M` with terminal states added: the states where `terminal` holds. Every other method
/// is the inner model's (its blocks, tables and goals included).
pub struct WithTerminals<M, F> {
    /// The model wrapped.
    pub inner: M,
    /// Whether a state is terminal.
    pub terminal: F,
}

impl<T: Real, M: Model<T>, F: Fn(&[T]) -> bool> Model<T> for WithTerminals<M, F> {
    fn state_dim(&self) -> usize {
        self.inner.state_dim()
    }
    fn n_agents(&self) -> usize {
        self.inner.n_agents()
    }
    fn action_set(&self, a: usize) -> fuzzyq_core::ActionSet<'_, T> {
        self.inner.action_set(a)
    }
    fn state_bounds(&self, d: usize) -> (T, T) {
        self.inner.state_bounds(d)
    }
    fn step(&self, x: &[T], u: &[T], next: &mut [T]) {
        self.inner.step(x, u, next);
    }
    fn reward(&self, x: &[T], u: &[T]) -> T {
        self.inner.reward(x, u)
    }
    fn reward_depends_on_action(&self) -> bool {
        self.inner.reward_depends_on_action()
    }
    fn reward_depends_on_state(&self, dim: usize) -> bool {
        self.inner.reward_depends_on_state(dim)
    }
    fn is_goal(&self, x: &[T]) -> bool {
        self.inner.is_goal(x)
    }
    fn is_terminal(&self, x: &[T]) -> bool {
        (self.terminal)(x)
    }
    fn has_terminal_states(&self) -> bool {
        true
    }
    fn n_blocks(&self) -> usize {
        self.inner.n_blocks()
    }
    fn block(&self, b: usize) -> fuzzyq_core::Block<'_> {
        self.inner.block(b)
    }
    fn block_rows(&self, b: usize) -> Option<fuzzyq_core::BlockRows<'_, T>> {
        self.inner.block_rows(b)
    }
    fn tabulated(&self) -> Option<fuzzyq_core::Tabulated<'_, T>> {
        self.inner.tabulated()
    }
    fn reward_table(&self) -> Option<&[T]> {
        self.inner.reward_table()
    }
}
