//! The solver against a brute-force reference, its two backup paths against each other, and
//! its invariants: contraction, determinism across thread counts, sync/async agreement.

use fuzzyq_core::NamedOption;
use std::ops::ControlFlow;

use fuzzyq_core::solver::{
    BackupPath, Buf, Grid, Kernel, Local, Operator, Solution, SolveError, SolverConfig,
    SolverState, Stop, SweepMode, Sweeps, solve, solve_from,
};
use fuzzyq_core::{ActionSet, Backup, Block, Model, Real};
use fuzzyq_sim::model::pointmass::{FrictionConfig, Integrator, PointMass, PointMassConfig};
use fuzzyq_tests::{
    Reference, WithTerminals, assert_close, brute_force, max_and_argmax, max_diff,
    medium_two_agent, small_one_agent, small_two_agent, with_threads,
};
use proptest::prelude::*;

fn config(path: BackupPath, sweep: SweepMode) -> SolverConfig {
    SolverConfig {
        path,
        sweep,
        ..SolverConfig::default()
    }
}

fn run<T: Real, M: Model<T> + Sync>(m: &M, g: &Grid<T>, c: &SolverConfig) -> Solution<T> {
    solve(m, g, c, |_| ControlFlow::Continue(())).expect("solve")
}

/// Deterministic pseudo-random values in `[lo, hi)`.
pub(crate) fn values<T: Real>(n: usize, seed: u64, lo: f64, hi: f64) -> Vec<T> {
    let mut s = seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            T::from_f64(lo + (hi - lo) * ((s >> 11) as f64 / (1u64 << 53) as f64))
        })
        .collect()
}

/// The generic path is the paper's iteration: same sweeps, bit-identical V, the exact
/// stopping rule, the same greedy actions.
/// A synchronous run of the small one-agent problem on `path` and the brute-force reference
/// of the same settings.
fn against_brute_force(
    path: BackupPath,
    absorbing: bool,
) -> (Solution<f64>, Reference<f64>, SolverConfig) {
    let (m, g) = small_one_agent::<f64>();
    let c = SolverConfig {
        absorbing_goal: absorbing,
        ..config(path, SweepMode::Synchronous)
    };
    let s = run(&m, &g, &c);
    let r = brute_force(&m, &g, c.gamma, c.xi, absorbing);
    (s, r, c)
}

#[test]
fn generic_path_matches_brute_force_exactly() {
    for absorbing in [false, true] {
        let (s, r, c) = against_brute_force(BackupPath::Generic, absorbing);
        assert_eq!(s.sweeps.len(), r.deltas.len(), "absorbing {absorbing}");
        assert!(s.converged());
        let (v, _) = max_and_argmax(&r.theta, 25);
        assert_eq!(s.v, v, "V is bit-identical to max_u theta_K");
        let (_, greedy) = max_and_argmax(&r.theta_next, 25);
        assert_eq!(s.greedy, greedy);
        for (rec, &exact) in s.sweeps.iter().zip(&r.deltas) {
            let d = rec.delta;
            assert!(
                d.lower <= exact + 1e-12 && exact <= d.upper + 1e-12,
                "sweep {}: {exact} outside [{}, {}]",
                rec.sweep,
                d.lower,
                d.upper
            );
        }
        assert!((s.final_delta - r.deltas.last().unwrap()).abs() < 1e-12);
        assert!(s.final_delta <= c.xi && r.deltas[r.deltas.len() - 2] > c.xi);
    }
}

#[test]
fn block_path_matches_brute_force() {
    for absorbing in [false, true] {
        let (s, r, _) = against_brute_force(BackupPath::Block, absorbing);
        assert_eq!(s.path, BackupPath::Block);
        assert_eq!(s.sweeps.len(), r.deltas.len());
        let (v, _) = max_and_argmax(&r.theta, 25);
        assert_close(&s.v, &v, 1e-10);
        assert!((s.final_delta - r.deltas.last().unwrap()).abs() < 1e-10);
    }
}

#[test]
fn block_and_generic_backups_agree_on_two_agents() {
    let (m, g) = small_two_agent::<f64>();
    let view = g.view();
    let backup = Backup::discounted(0.96);
    let block = Operator::new(&m, view, backup, BackupPath::Block).unwrap();
    let generic = Operator::new(&m, view, backup, BackupPath::Generic).unwrap();
    let v = values::<f64>(g.n_cores(), 7, -50.0, 120.0);
    let (tb, tg) = (block.apply(&v).unwrap(), generic.apply(&v).unwrap());
    assert_close(&tb, &tg, 1e-9);
    let (gb, gg) = (block.greedy(&v).unwrap(), generic.greedy(&v).unwrap());
    // Greedy actions agree except where two actions are within rounding of each other.
    let mut q = vec![0.0; 625];
    let mut x = vec![0.0; 8];
    let mut differ = 0;
    for d in 0..g.n_cores() {
        if gb[d] != gg[d] {
            differ += 1;
            view.core_state(d, &mut x).unwrap();
            generic.q_values(&v, &x, &mut q).unwrap();
            assert!((q[gb[d] as usize] - q[gg[d] as usize]).abs() < 1e-9);
        }
    }
    assert!(differ < g.n_cores() / 100, "{differ} cores differ");
}

/// The in-process backend's greedy backup (values and actions in one pass) gives the plain
/// backup's values and the greedy pass's actions, bit for bit, on both paths.
#[test]
fn greedy_backups_give_the_backup_and_the_greedy_actions_on_both_paths() {
    let (m, g) = small_two_agent::<f64>();
    let backup = Backup::discounted(0.96);
    for path in [BackupPath::Block, BackupPath::Generic] {
        let op = Operator::new(&m, g.view(), backup, path).unwrap();
        let v = values::<f64>(g.n_cores(), 7, -50.0, 120.0);
        let mut local = Local::new(&op);
        local.load(Buf(0), &v).unwrap();
        local.backup(Buf(0), Buf(2)).unwrap();
        local.greedy(Buf(0)).unwrap();
        let greedy = local.policy().unwrap().into_owned();
        local.load_policy(&vec![0; g.n_cores()]).unwrap();
        local.backup_greedy(Buf(0), Buf(1)).unwrap();
        let (got, want) = (local.values(Buf(1)).unwrap(), local.values(Buf(2)).unwrap());
        let bits = |x: &[f64]| x.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&got), bits(&want), "{path:?}: values");
        assert_eq!(
            local.policy().unwrap().as_ref(),
            &greedy[..],
            "{path:?}: actions"
        );
        assert!(
            greedy.iter().any(|&u| u != 0),
            "{path:?}: a policy of more than action 0"
        );
    }
}

/// With absorbing goals, a goal core's backup is its reward whatever `V` is, and its greedy
/// action is 0, on the block path as on the generic one (the block path finishes whole runs
/// of cores at once, goal cores among them).
#[test]
fn absorbing_goal_cores_take_action_zero_on_both_paths() {
    let (m, g) = small_two_agent::<f64>();
    let backup = Backup {
        gamma: 0.96,
        absorbing_goal: true,
    };
    let block = Operator::new(&m, g.view(), backup, BackupPath::Block).unwrap();
    let generic = Operator::new(&m, g.view(), backup, BackupPath::Generic).unwrap();
    let v = values::<f64>(g.n_cores(), 7, -50.0, 120.0);
    let w = values::<f64>(g.n_cores(), 11, 300.0, 900.0);
    let (tb, tg) = (block.apply(&v).unwrap(), generic.apply(&v).unwrap());
    assert_close(&tb, &tg, 1e-9);
    let (gb, gg) = (block.greedy(&v).unwrap(), generic.greedy(&v).unwrap());
    // Goal cores: the backup does not depend on `V`.
    let tw = block.apply(&w).unwrap();
    let goals: Vec<usize> = (0..g.n_cores()).filter(|&d| tb[d] == tw[d]).collect();
    assert!(
        !goals.is_empty() && goals.len() < g.n_cores() / 2,
        "{} goal cores",
        goals.len()
    );
    for &d in &goals {
        assert_eq!((gb[d], gg[d]), (0, 0), "goal core {d}");
    }
    // Elsewhere the greedy actions are mostly not 0 (so the check above can fail).
    assert!(gb.iter().filter(|&&u| u != 0).count() > g.n_cores() / 2);
}

#[test]
fn decisions_agree_between_paths_at_any_state() {
    let (m, g) = small_two_agent::<f64>();
    for absorbing in [false, true] {
        let backup = Backup {
            gamma: 0.96,
            absorbing_goal: absorbing,
        };
        let block = Operator::new(&m, g.view(), backup, BackupPath::Block).unwrap();
        let generic = Operator::new(&m, g.view(), backup, BackupPath::Generic).unwrap();
        let v = values::<f64>(g.n_cores(), 11, 0.0, 100.0);
        let (mut qb, mut qg) = (vec![0.0; 625], vec![0.0; 625]);
        let states = values::<f64>(8 * 20, 3, -1.0, 1.0);
        for (i, s) in states.chunks(8).enumerate() {
            // Scale into the state box; the first state sits on the goal core.
            let x: Vec<f64> = if i == 0 {
                vec![0.0; 8]
            } else {
                s.iter()
                    .enumerate()
                    .map(|(j, &u)| if j % 4 < 2 { 6.0 * u } else { 3.0 * u })
                    .collect()
            };
            block.q_values(&v, &x, &mut qb).unwrap();
            generic.q_values(&v, &x, &mut qg).unwrap();
            assert_close(&qb, &qg, 1e-9);
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// `||T V1 - T V2||_inf <= gamma ||V1 - V2||_inf` for both paths.
    #[test]
    fn backup_is_a_gamma_contraction(
        seed in any::<u64>(),
        gamma in 0.0..0.999f64,
        absorbing in any::<bool>(),
        generic in any::<bool>(),
    ) {
        let (m, g) = small_one_agent::<f64>();
        let path = if generic { BackupPath::Generic } else { BackupPath::Block };
        let op = Operator::new(&m, g.view(), Backup { gamma, absorbing_goal: absorbing }, path)
            .unwrap();
        let v1 = values::<f64>(g.n_cores(), seed, -100.0, 100.0);
        let v2 = values::<f64>(g.n_cores(), seed ^ 0xABCD, -100.0, 100.0);
        let lhs = max_diff(&op.apply(&v1).unwrap(), &op.apply(&v2).unwrap());
        let rhs = gamma * max_diff(&v1, &v2);
        prop_assert!(lhs <= rhs + 1e-9, "{lhs} > {rhs}");
    }
}

/// Synchronous and asynchronous sweeps stop within their error bounds of the same fixed
/// point; asynchronous sweeps need fewer of them.
#[test]
fn sync_and_async_reach_the_same_fixed_point() {
    let xi = 1e-5;
    let both = |m: &dyn Fn(&SolverConfig) -> Solution<f64>, path| {
        [SweepMode::Synchronous, SweepMode::Asynchronous].map(|sweep| {
            m(&SolverConfig {
                xi,
                ..config(path, sweep)
            })
        })
    };
    let (m, g) = medium_two_agent::<f64>();
    let [sync, asy] = both(&|c| run(&m, &g, c), BackupPath::Block);
    assert!(sync.converged() && asy.converged());
    let bound = 2.0 * 0.96 / 0.04 * xi;
    let d = max_diff(&sync.v, &asy.v);
    assert!(d <= bound, "{d} > {bound}");
    // Not a trivial fixed point: the reward propagates over hundreds of sweeps.
    assert!(sync.sweeps.len() > 200 && asy.sweeps.len() > 100);
    assert!(sync.v.iter().cloned().fold(0.0, f64::max) > 50.0);

    // Generic asynchronous sweeps (different slabs) reach it too.
    let (m1, g1) = small_one_agent::<f64>();
    let [s, a] = both(&|c| run(&m1, &g1, c), BackupPath::Generic);
    assert!(max_diff(&a.v, &s.v) <= bound);
}

/// Bit-identical results for 1, 2 and 3 threads, on every path and sweep mode.
#[test]
fn results_do_not_depend_on_thread_count() {
    let (m, medium) = medium_two_agent::<f32>();
    let (_, small) = small_two_agent::<f32>();
    for (path, sweep, max_sweeps, extrapolate, evaluation_sweeps) in [
        (BackupPath::Block, SweepMode::Synchronous, 1000, false, 0),
        (BackupPath::Block, SweepMode::Synchronous, 1000, true, 0),
        (BackupPath::Block, SweepMode::Synchronous, 1000, true, 5),
        (BackupPath::Block, SweepMode::Asynchronous, 1000, false, 0),
        (BackupPath::Generic, SweepMode::Synchronous, 4, true, 0),
        (BackupPath::Generic, SweepMode::Asynchronous, 4, false, 0),
    ] {
        let c = SolverConfig {
            max_sweeps,
            extrapolate,
            evaluation_sweeps,
            ..config(path, sweep)
        };
        let g = if path == BackupPath::Block {
            &medium
        } else {
            &small
        };
        let runs: Vec<Solution<f32>> = [1, 2, 3]
            .into_iter()
            .map(|n| with_threads(n, || run(&m, g, &c)))
            .collect();
        assert!(
            runs[0].v.iter().any(|&v| v > 0.0),
            "{path:?} {sweep:?}: trivial V"
        );
        for r in &runs[1..] {
            assert_eq!(r.v, runs[0].v, "{path:?} {sweep:?}");
            assert_eq!(r.greedy, runs[0].greedy);
            assert_eq!(r.final_delta.to_bits(), runs[0].final_delta.to_bits());
            let deltas = |s: &Solution<f32>| s.sweeps.iter().map(|r| r.delta).collect::<Vec<_>>();
            assert_eq!(deltas(r), deltas(&runs[0]));
        }
    }
}

/// `f32` and `f64` solves agree: the same sweeps and V within 1e-4 relative.
#[test]
fn single_and_double_precision_agree() {
    let (m, g32) = medium_two_agent::<f32>();
    let (_, g64) = medium_two_agent::<f64>();
    let c = config(BackupPath::Auto, SweepMode::Synchronous);
    let a = run(&m, &g32, &c);
    let b = run(&m, &g64, &c);
    assert_eq!(a.sweeps.len(), b.sweeps.len());
    assert!(a.sweeps.len() > 100);
    for (x, y) in a.v.iter().zip(&b.v) {
        assert!((f64::from(*x) - y).abs() <= 1e-4 * y.abs().max(1.0));
    }
}

#[test]
fn absorbing_goal_pins_goal_cores_to_their_reward() {
    let (m, g) = small_one_agent::<f64>();
    let s = run(
        &m,
        &g,
        &SolverConfig {
            absorbing_goal: true,
            ..SolverConfig::default()
        },
    );
    let view = g.view();
    let mut x = vec![0.0; 4];
    let origin = (0..g.n_cores())
        .find(|&d| {
            view.core_state(d, &mut x).unwrap();
            x.iter().all(|&v| v == 0.0)
        })
        .unwrap();
    assert_eq!(s.v[origin], 5.0);
    let plain = run(&m, &g, &SolverConfig::default());
    assert!(plain.v[origin] > 100.0);
}

#[test]
fn sweep_limit_and_interruption() {
    let (m, g) = small_one_agent::<f32>();
    let s = run(
        &m,
        &g,
        &SolverConfig {
            max_sweeps: 3,
            ..SolverConfig::default()
        },
    );
    assert_eq!(s.stop, Stop::SweepLimit);
    assert_eq!(s.sweeps.len(), 3);
    assert!(s.final_delta.is_finite());
    let e = solve(&m, &g, &SolverConfig::default(), |p| {
        if p.record.sweep == 2 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .unwrap_err();
    assert_eq!(e, SolveError::Interrupted { sweeps: 2 });
}

#[test]
fn invalid_settings_are_refused() {
    let (m, g) = small_one_agent::<f32>();
    let bad = |c: SolverConfig| solve(&m, &g, &c, |_| ControlFlow::Continue(())).unwrap_err();
    assert_eq!(
        bad(SolverConfig {
            gamma: 1.0,
            ..SolverConfig::default()
        }),
        SolveError::Gamma(1.0)
    );
    assert!(matches!(
        bad(SolverConfig {
            xi: 0.0,
            ..SolverConfig::default()
        }),
        SolveError::Xi(_)
    ));
    let g2 = fuzzyq_tests::grid::<f32>(2, &[-1.0, 1.0], &[-1.0, 1.0]);
    let e = solve(&m, &g2, &SolverConfig::default(), |_| {
        ControlFlow::Continue(())
    })
    .unwrap_err();
    assert_eq!(e, SolveError::StateDim { model: 4, grid: 8 });
}

/// A model that declares the constant-friction blocks while its friction depends on
/// position: the solver must refuse the declaration rather than compute a wrong backup.
struct WrongBlocks(PointMass);

impl Model<f64> for WrongBlocks {
    fn state_dim(&self) -> usize {
        4
    }
    fn n_agents(&self) -> usize {
        1
    }
    fn action_set(&self, a: usize) -> ActionSet<'_, f64> {
        self.0.action_set(a)
    }
    fn state_bounds(&self, d: usize) -> (f64, f64) {
        Model::<f64>::state_bounds(&self.0, d)
    }
    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        self.0.step(x, u, next)
    }
    fn reward(&self, x: &[f64], u: &[f64]) -> f64 {
        self.0.reward(x, u)
    }
    fn n_blocks(&self) -> usize {
        2
    }
    fn block(&self, b: usize) -> Block<'_> {
        const DIMS: [[usize; 2]; 2] = [[0, 2], [1, 3]];
        const COMPS: [[usize; 1]; 2] = [[0], [1]];
        Block {
            state_dims: &DIMS[b],
            action_components: &COMPS[b],
        }
    }
}

#[test]
fn wrong_block_declarations_are_refused() {
    let field = PointMass::new(PointMassConfig {
        agents: 1,
        integrator: Integrator::Rk4,
        friction: FrictionConfig::Patches {
            base: 1.0,
            patches: vec![fuzzyq_sim::model::pointmass::FrictionPatch {
                center: [0.5, 0.5],
                radius: 1.0,
                eta: 4.0,
            }],
        },
        ..PointMassConfig::default()
    })
    .unwrap();
    // Its own declaration (one 4-variable block) is right, and agrees with the generic path.
    let (_, g) = small_one_agent::<f64>();
    let b = run(
        &field,
        &g,
        &config(BackupPath::Block, SweepMode::Synchronous),
    );
    let gen_ = run(
        &field,
        &g,
        &config(BackupPath::Generic, SweepMode::Synchronous),
    );
    assert_eq!(b.sweeps.len(), gen_.sweeps.len());
    assert_close(&b.v, &gen_.v, 1e-9);
    // Per-axis blocks are wrong for it.
    let e = solve(
        &WrongBlocks(field),
        &g,
        &config(BackupPath::Block, SweepMode::Synchronous),
        |_| ControlFlow::Continue(()),
    )
    .unwrap_err();
    assert!(matches!(e, SolveError::BlockMismatch { .. }), "{e}");
}

#[test]
fn grid_must_span_a_valid_partition() {
    let e = Grid::<f32>::new(vec![vec![0.0, 1.0], vec![2.0]]).unwrap_err();
    assert_eq!(
        e.to_string(),
        "state variable 1: a partition needs at least 2 cores, found 1"
    );
}

/// Every kernel instance this CPU runs gives the same solution, bit for bit.
#[test]
fn kernel_instances_give_identical_solutions() {
    let (m, g) = medium_two_agent::<f32>();
    let runs: Vec<(Kernel, Solution<f32>)> = Kernel::ALL
        .iter()
        .copied()
        .filter(|k| k.is_available())
        .map(|k| {
            let c = SolverConfig {
                kernel: Some(k),
                extrapolate: true,
                evaluation_sweeps: 5,
                ..SolverConfig::default()
            };
            (k, run(&m, &g, &c))
        })
        .collect();
    assert!(runs.iter().any(|(k, _)| *k == Kernel::Scalar));
    let (_, reference) = runs.last().expect("scalar runs everywhere");
    for (k, s) in &runs {
        assert_eq!(s.kernel, k.name());
        assert_eq!(s.v, reference.v, "{k:?}");
        assert_eq!(s.greedy, reference.greedy, "{k:?}");
        assert_eq!(s.sweeps.len(), reference.sweeps.len(), "{k:?}");
    }
}

/// The fixed point to within `1e-9` (value iteration, extrapolated), for error measurements.
fn tight_reference<M: Model<f64> + Sync>(m: &M, g: &Grid<f64>) -> Solution<f64> {
    run(
        m,
        g,
        &SolverConfig {
            xi: 1e-9,
            extrapolate: true,
            ..SolverConfig::default()
        },
    )
}

/// Extrapolated and plain sweeps both stop within gamma xi / (1 - gamma) of the fixed point;
/// extrapolation needs fewer sweeps.
#[test]
fn extrapolation_stops_within_the_same_bound_in_fewer_sweeps() {
    let (m, g) = medium_two_agent::<f64>();
    let reference = tight_reference(&m, &g);
    let xi = 0.05;
    let bound = 0.96 * xi / 0.04;
    let plain = run(&m, &g, &SolverConfig::default());
    let fast = run(
        &m,
        &g,
        &SolverConfig {
            extrapolate: true,
            ..SolverConfig::default()
        },
    );
    assert!(plain.converged() && fast.converged());
    for s in [&plain, &fast] {
        let err = max_diff(&s.v, &reference.v);
        assert!(err <= bound, "error {err} > bound {bound}");
        assert!(s.final_delta <= xi);
    }
    assert!(
        fast.sweeps.len() * 2 < plain.sweeps.len(),
        "{} vs {} sweeps",
        fast.sweeps.len(),
        plain.sweeps.len()
    );
    // The absorbing goal breaks the constant-shift property: no extrapolation then.
    let c = SolverConfig {
        absorbing_goal: true,
        ..SolverConfig::default()
    };
    let a = run(&m, &g, &c);
    let b = run(
        &m,
        &g,
        &SolverConfig {
            extrapolate: true,
            ..c
        },
    );
    assert_eq!(a.v, b.v);
}

/// A policy-evaluation sweep under the greedy actions of `V` is the full backup of `V`, bit for
/// bit, on every kernel instance: one agent (2 blocks: the first stage action-major, the last
/// stage reading it transposed), two and three agents (4 and 6 blocks, so the stage before
/// the last two runs action-major from a middle stage), `V` from 30 sweeps. Operators that
/// cannot evaluate say so, and bad policies are refused.
#[test]
fn evaluating_the_greedy_policy_gives_the_full_backup() {
    let three = PointMass::new(PointMassConfig {
        agents: 3,
        force_levels: vec![-2.0, 2.0],
        ..PointMassConfig::default()
    })
    .unwrap();
    let one = PointMass::new(PointMassConfig {
        agents: 1,
        ..PointMassConfig::default()
    })
    .unwrap();
    let pos = [-6.0, -4.0, -2.0, -0.5, 0.0, 0.5, 2.0, 4.0, 6.0];
    let problems = [
        (
            one,
            fuzzyq_tests::grid::<f32>(1, &pos, &[-3.0, -1.0, 0.0, 1.0, 3.0]),
        ),
        (medium_two_agent::<f32>().0, medium_two_agent::<f32>().1),
        (
            three,
            fuzzyq_tests::grid::<f32>(3, &[-6.0, 0.0, 6.0], &[-3.0, 0.0, 3.0]),
        ),
    ];
    let backup = Backup::discounted(0.96);
    for (m, g) in &problems {
        let v = run(
            m,
            g,
            &SolverConfig {
                max_sweeps: 30,
                ..SolverConfig::default()
            },
        )
        .v;
        for &k in Kernel::ALL.iter().filter(|k| k.is_available()) {
            let op = Operator::new(m, g.view(), backup, BackupPath::Block)
                .unwrap()
                .with_kernel(k)
                .unwrap();
            let greedy = op.greedy(&v).unwrap();
            let full = op.apply(&v).unwrap();
            let ev = op.evaluate_policy(&v, &greedy).unwrap();
            let bits = |x: &[f32]| x.iter().map(|y| y.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&ev),
                bits(&full),
                "{} cores, {}",
                g.n_cores(),
                k.name()
            );
            // Another policy evaluates to something else, never above the maximum.
            let n = op.joint().n_joint() as u32;
            let other: Vec<u32> = greedy.iter().map(|&u| (u + n / 2) % n).collect();
            let ev = op.evaluate_policy(&v, &other).unwrap();
            assert!(ev.iter().zip(&full).all(|(e, f)| e <= f));
            assert!(ev != full);
            assert!(matches!(
                op.evaluate_policy(&v, &vec![n; v.len()]),
                Err(SolveError::Eval(_))
            ));
            assert!(matches!(
                op.evaluate_policy(&v, &greedy[1..]),
                Err(SolveError::Eval(_))
            ));
        }
    }
    let (m, g) = medium_two_agent::<f32>();
    let absorbing = Backup {
        absorbing_goal: true,
        ..backup
    };
    let op = Operator::new(&m, g.view(), absorbing, BackupPath::Block).unwrap();
    let v = vec![0.0f32; g.n_cores()];
    assert_eq!(
        op.evaluate_policy(&v, &vec![0; v.len()]),
        Err(SolveError::PolicyEvaluation)
    );
}

/// Modified policy iteration stops by the span rule within the paper's guarantee
/// `gamma/(1-gamma) xi` of a tightly converged reference, in fewer full backups than value
/// iteration needs sweeps; its greedy actions are those of the returned `V`; where its
/// conditions fail, value iteration runs.
#[test]
fn modified_policy_iteration_stops_within_the_same_bound_in_fewer_full_backups() {
    use fuzzyq_core::solver::Scheme;
    let (m, g) = medium_two_agent::<f64>();
    let reference = tight_reference(&m, &g);
    let gamma = 0.96;
    let mut returned_input = Vec::new();
    for xi in [0.5, 0.05, 0.005] {
        let value = run(
            &m,
            &g,
            &SolverConfig {
                xi,
                extrapolate: true,
                ..SolverConfig::default()
            },
        );
        let mpi = run(
            &m,
            &g,
            &SolverConfig {
                xi,
                extrapolate: true,
                evaluation_sweeps: 5,
                ..SolverConfig::default()
            },
        );
        assert_eq!(value.scheme, Scheme::Value);
        assert_eq!(mpi.scheme, Scheme::ModifiedPolicy);
        assert!(mpi.converged() && mpi.final_delta <= xi);
        assert!(mpi.evaluation_sweeps() > 0);
        let err = max_diff(&mpi.v, &reference.v);
        let bound = mpi.error_bound(gamma);
        assert!(
            err <= bound + 1e-9,
            "xi {xi}: error {err} > its bound {bound}"
        );
        assert!(bound <= gamma / (1.0 - gamma) * xi);
        assert!(
            mpi.full_backups() < value.sweeps.len(),
            "xi {xi}: {} full backups vs {} sweeps",
            mpi.full_backups(),
            value.sweeps.len()
        );
        let op = Operator::new(&m, g.view(), Backup::discounted(gamma), BackupPath::Block).unwrap();
        assert_eq!(op.greedy(&mpi.v).unwrap(), mpi.greedy);
        // Which `V` the run returned: the last full backup's input (final delta = its change
        // over gamma) or its midpoint-shifted result (final delta = its half-span).
        let last = mpi.sweeps.last().unwrap();
        assert!(!last.evaluation);
        if mpi.final_delta == last.delta_v / gamma {
            returned_input.push(xi);
            let change = max_diff(&op.apply(&mpi.v).unwrap(), &mpi.v);
            assert_eq!(change, last.delta_v);
            assert!(change <= gamma * xi);
        } else {
            assert_eq!(mpi.final_delta, last.delta.upper);
        }
    }
    // Both returns are exercised above.
    assert!(
        !returned_input.is_empty() && returned_input.len() < 3,
        "returned the backup's input for xi in {returned_input:?}"
    );
    // Absorbing goals, asynchronous sweeps and the generic path run value iteration.
    for c in [
        SolverConfig {
            absorbing_goal: true,
            ..SolverConfig::default()
        },
        config(BackupPath::Block, SweepMode::Asynchronous),
        SolverConfig {
            max_sweeps: 3,
            ..config(BackupPath::Generic, SweepMode::Synchronous)
        },
    ] {
        let c = SolverConfig {
            extrapolate: true,
            evaluation_sweeps: 5,
            ..c
        };
        let s = run(&m, &g, &c);
        assert_eq!(s.scheme, Scheme::Value, "{c:?}");
        assert_eq!(s.evaluation_sweeps(), 0);
    }
}

/// A model given only as a table at the cores (as a Python callable is) solves to the same `V`
/// as the model itself, bit for bit, and its policy decisions agree.
#[test]
fn tabulated_model_matches_the_model_it_tabulates() {
    use fuzzyq_core::solver::TabulatedModel;
    let (m, g) = small_one_agent::<f64>();
    let view = g.view();
    let joint = fuzzyq_core::model::joint_actions(&m).unwrap();
    let (n, mj, e) = (g.n_cores(), joint.n_joint(), g.n_dims());
    let mut next = vec![0.0; n * mj * e];
    let mut rewards = vec![0.0; n * mj];
    let (mut x, mut u) = (vec![0.0; e], vec![0.0; joint.dim()]);
    for d in 0..n {
        view.core_state(d, &mut x).unwrap();
        for a in 0..mj {
            joint.vector(a, &mut u).unwrap();
            let i = d * mj + a;
            m.step(&x, &u, &mut next[i * e..(i + 1) * e]);
            rewards[i] = m.reward(&x, &u);
        }
    }
    let set = Model::<f64>::action_set(&m, 0);
    let t =
        TabulatedModel::new(g.clone(), vec![(set.values().to_vec(), 2)], next, rewards).unwrap();
    let c = SolverConfig {
        extrapolate: true,
        ..config(BackupPath::Generic, SweepMode::Synchronous)
    };
    let a = run(&m, &g, &c);
    let b = run(&t, &g, &c);
    assert_eq!(b.path, BackupPath::Generic);
    assert_eq!(a.v, b.v);
    assert_eq!(a.sweeps.len(), b.sweeps.len());
    // Decisions at states between cores.
    let backup = Backup::discounted(0.96);
    let oa = Operator::new(&m, g.view(), backup, BackupPath::Generic).unwrap();
    let ob = Operator::new(&t, g.view(), backup, BackupPath::Auto).unwrap();
    let (mut qa, mut qb) = (vec![0.0; 25], vec![0.0; 25]);
    for x in [
        [-4.0, 3.0, 1.0, -2.0],
        [0.3, -0.2, 0.1, 0.0],
        [5.9, -5.9, 2.9, -2.9],
    ] {
        oa.q_values(&a.v, &x, &mut qa).unwrap();
        ob.q_values(&b.v, &x, &mut qb).unwrap();
        assert_close(&qa, &qb, 1e-9);
    }
    // Shapes are checked.
    let bad = TabulatedModel::new(
        g.clone(),
        vec![(set.values().to_vec(), 2)],
        vec![0.0; 3],
        vec![0.0; 3],
    );
    assert!(bad.is_err());
}

/// Crisp grid Q-iteration computed independently: every successor is aggregated into the
/// core nearest to it in each variable.
fn crisp_reference(m: &PointMass, g: &Grid<f64>, gamma: f64, sweeps: usize) -> Vec<f64> {
    let view = g.view();
    let joint = fuzzyq_core::model::joint_actions::<f64, _>(m).unwrap();
    let (n, nj, e) = (g.n_cores(), joint.n_joint(), g.n_dims());
    let (mut x, mut next, mut u) = (vec![0.0; e], vec![0.0; e], vec![0.0; joint.dim()]);
    let mut table = Vec::with_capacity(n * nj);
    for d in 0..n {
        view.core_state(d, &mut x).unwrap();
        for a in 0..nj {
            joint.vector(a, &mut u).unwrap();
            Model::<f64>::step(m, &x, &u, &mut next);
            let mut index = 0;
            for (dim, cores) in g.cores().iter().enumerate() {
                let nearest = (0..cores.len())
                    .min_by(|&i, &j| {
                        let (di, dj) = ((next[dim] - cores[i]).abs(), (next[dim] - cores[j]).abs());
                        // The midpoint belongs to the upper core.
                        di.partial_cmp(&dj).unwrap().then(j.cmp(&i))
                    })
                    .unwrap();
                index = index * cores.len() + nearest;
            }
            table.push((Model::<f64>::reward(m, &x, &u), index));
        }
    }
    let mut v = vec![0.0; n];
    for _ in 0..sweeps {
        v = (0..n)
            .map(|d| {
                table[d * nj..(d + 1) * nj]
                    .iter()
                    .map(|&(r, k)| r + gamma * v[k])
                    .fold(f64::NEG_INFINITY, f64::max)
            })
            .collect();
    }
    v
}

/// A crisp grid runs through both backup paths as a state aggregation: both equal the
/// independent nearest-core reference.
#[test]
fn crisp_grid_iteration_matches_the_nearest_core_reference() {
    use fuzzyq_core::Membership;
    let (m, g) = small_one_agent::<f64>();
    let g = g.with_membership(Membership::Crisp);
    for path in [BackupPath::Generic, BackupPath::Block] {
        let c = SolverConfig {
            extrapolate: false,
            ..config(path, SweepMode::Synchronous)
        };
        let s = run(&m, &g, &c);
        let reference = crisp_reference(&m, &g, c.gamma, s.sweeps.len());
        assert_close(&s.v, &reference, 1e-10);
    }
    // And the crisp fixed point is not the fuzzy one on this grid (successors fall between
    // cores), so the test above would notice memberships that stayed triangular.
    let (m, fuzzy) = small_one_agent::<f64>();
    let c = SolverConfig {
        extrapolate: false,
        ..config(BackupPath::Generic, SweepMode::Synchronous)
    };
    let crisp = run(&m, &fuzzy.clone().with_membership(Membership::Crisp), &c);
    assert!(max_diff(&run(&m, &fuzzy, &c).v, &crisp.v) > 0.1);
}

/// Where every successor of every core is itself a core, crisp and fuzzy Q-iteration are
/// the same iteration: bit-identical values and greedy actions.
#[test]
fn crisp_equals_fuzzy_when_successors_are_cores() {
    use fuzzyq_core::Membership;
    let fuzzy = Grid::new(vec![(0..9).map(f64::from).collect()]).unwrap();
    let crisp = fuzzy.clone().with_membership(Membership::Crisp);
    let m = Chain;
    let c = config(BackupPath::Generic, SweepMode::Synchronous);
    let (a, b) = (run(&m, &fuzzy, &c), run(&m, &crisp, &c));
    assert_eq!(a.v, b.v);
    assert_eq!(a.greedy, b.greedy);
    assert_eq!(a.sweeps.len(), b.sweeps.len());
    assert!(a.v[0] > 0.0, "the reward is reachable from the far end");
    // Both solve the chain: move right (action 2) until the end.
    assert!(b.greedy[..8].iter().all(|&u| u == 2), "{:?}", b.greedy);
}

/// Integer positions 0..=8, moves of -1, 0, +1 (clamped), reward 1 at 8.
struct Chain;

impl Model<f64> for Chain {
    fn state_dim(&self) -> usize {
        1
    }
    fn n_agents(&self) -> usize {
        1
    }
    fn action_set(&self, _: usize) -> ActionSet<'_, f64> {
        ActionSet::try_new(&[-1.0, 0.0, 1.0], 1).unwrap()
    }
    fn state_bounds(&self, _: usize) -> (f64, f64) {
        (0.0, 8.0)
    }
    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        next[0] = (x[0] + u[0]).clamp(0.0, 8.0);
    }
    fn reward(&self, x: &[f64], _: &[f64]) -> f64 {
        f64::from(u8::from(x[0] == 8.0))
    }
}

// ---------------------------------------------------------------------------------------------
// Terminal states.

/// Independent "cliff" coordinates: each moves as `x' = a x + u + c` and the episode ends when
/// any coordinate leaves `[0, 4]` (+10 for leaving at the top of the last coordinate, -5
/// otherwise). One state variable per block, one action component per block; 1 or 2
/// coordinates. Optional: an action-independent reward, an absorbing goal core, terminal
/// states switched off (same `is_terminal`, but not declared), and the first coordinate
/// clamped to `[0, 4]` instead (so that only some slabs of the block path see terminal pairs).
pub(crate) struct Cliff<T> {
    dims: usize,
    actions: Vec<T>,
    action_reward: bool,
    terminal: bool,
    clamp_first: bool,
}

const CLIFF_A: [f64; 2] = [1.05, 0.95];
const CLIFF_C: [f64; 2] = [0.0, 0.2];
const CLIFF_LEVELS: [[f64; 3]; 2] = [[-1.0, 0.0, 0.8], [-0.9, 0.0, 1.2]];

impl<T: Real> Cliff<T> {
    pub(crate) fn new(dims: usize, action_reward: bool) -> Self {
        let actions = if dims == 1 {
            [-1.3, -0.4, 0.0, 0.5, 1.1]
                .iter()
                .map(|&a| T::from_f64(a))
                .collect()
        } else {
            let mut a = Vec::new();
            for ux in CLIFF_LEVELS[0] {
                for uy in CLIFF_LEVELS[1] {
                    a.push(T::from_f64(ux));
                    a.push(T::from_f64(uy));
                }
            }
            a
        };
        Self {
            dims,
            actions,
            action_reward,
            terminal: true,
            clamp_first: false,
        }
    }

    pub(crate) fn grid(&self) -> Grid<T> {
        let cores: [&[f64]; 2] = [
            &[0.0, 0.5, 1.2, 2.0, 2.6, 3.3, 4.0],
            &[0.0, 1.0, 1.8, 2.9, 4.0],
        ];
        Grid::new(
            cores[..self.dims]
                .iter()
                .map(|c| c.iter().map(|&v| T::from_f64(v)).collect())
                .collect(),
        )
        .unwrap()
    }

    fn next(&self, x: &[T], u: &[T], i: usize) -> f64 {
        let n = CLIFF_A[i] * x[i].to_f64() + u[i].to_f64() + CLIFF_C[i];
        if i == 0 && self.clamp_first {
            n.clamp(0.0, 4.0)
        } else {
            n
        }
    }

    fn outside(v: f64) -> bool {
        !(0.0..=4.0).contains(&v)
    }
}

impl<T: Real> Model<T> for Cliff<T> {
    fn state_dim(&self) -> usize {
        self.dims
    }
    fn n_agents(&self) -> usize {
        1
    }
    fn action_set(&self, _: usize) -> ActionSet<'_, T> {
        ActionSet::try_new(&self.actions, self.dims).unwrap()
    }
    fn state_bounds(&self, _: usize) -> (T, T) {
        (T::ZERO, T::from_f64(4.0))
    }
    fn step(&self, x: &[T], u: &[T], next: &mut [T]) {
        for (i, n) in next.iter_mut().enumerate() {
            *n = T::from_f64(self.next(x, u, i));
        }
    }
    fn reward(&self, x: &[T], u: &[T]) -> T {
        if !self.action_reward {
            return T::from_f64(x[0].to_f64() / 4.0 - 1.0);
        }
        let next: Vec<f64> = (0..self.dims).map(|i| self.next(x, u, i)).collect();
        let (last, others) = next.split_last().unwrap();
        let r = if *last > 4.0 && !others.iter().any(|&v| Self::outside(v)) {
            10.0
        } else if next.iter().any(|&v| Self::outside(v)) {
            -5.0
        } else {
            -0.1 - 0.01 * u.iter().map(|v| v.to_f64().powi(2)).sum::<f64>()
        };
        T::from_f64(r)
    }
    fn reward_depends_on_action(&self) -> bool {
        self.action_reward
    }
    fn is_goal(&self, x: &[T]) -> bool {
        x[0].to_f64() == 2.0
    }
    fn is_terminal(&self, x: &[T]) -> bool {
        x.iter().any(|v| Self::outside(v.to_f64()))
    }
    fn has_terminal_states(&self) -> bool {
        self.terminal
    }
    fn n_blocks(&self) -> usize {
        self.dims
    }
    fn block(&self, b: usize) -> Block<'_> {
        const DIMS: [[usize; 1]; 2] = [[0], [1]];
        Block {
            state_dims: &DIMS[b],
            action_components: &DIMS[b],
        }
    }
}

/// Every `greedy[d]` attains `max_u theta[d, u]` within `tol`.
fn assert_maximisers(greedy: &[u32], theta: &[f64], m: usize, tol: f64) {
    for (d, (&u, row)) in greedy.iter().zip(theta.chunks(m)).enumerate() {
        let best = row.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        assert!(
            row[u as usize] >= best - tol,
            "core {d}: {row:?}, greedy {u}"
        );
    }
}

/// Terminal successors: the generic path is the brute-force iteration bit for bit (sweeps, V,
/// greedy actions), the block path matches it to rounding, both with and without an absorbing
/// goal and for action-dependent and state-only rewards; asynchronous sweeps reach the same
/// fixed point.
#[test]
fn terminal_states_match_brute_force_on_every_path() {
    for (dims, clamp_first) in [(1, false), (2, false), (2, true)] {
        for action_reward in [true, false] {
            for absorbing in [false, true] {
                let m = Cliff {
                    clamp_first,
                    ..Cliff::<f64>::new(dims, action_reward)
                };
                let g = m.grid();
                let nj = fuzzyq_core::model::joint_actions(&m).unwrap().n_joint();
                let c = SolverConfig {
                    absorbing_goal: absorbing,
                    xi: 1e-6,
                    // Ignored: terminal states break the shift property.
                    extrapolate: true,
                    ..config(BackupPath::Generic, SweepMode::Synchronous)
                };
                let Reference {
                    theta,
                    theta_next,
                    deltas,
                } = brute_force(&m, &g, c.gamma, c.xi, absorbing);
                let (v, _) = max_and_argmax(&theta, nj);
                let (_, greedy) = max_and_argmax(&theta_next, nj);
                let what = format!(
                    "dims {dims}, clamp {clamp_first}, action reward {action_reward}, \
                     absorbing {absorbing}"
                );
                let s = run(&m, &g, &c);
                assert_eq!(s.path, BackupPath::Generic);
                assert_eq!(s.sweeps.len(), deltas.len(), "{what}");
                assert!(s.sweeps.iter().all(|r| !r.extrapolated), "{what}");
                assert_eq!(s.v, v, "{what}: V is bit-identical");
                if action_reward {
                    assert_eq!(s.greedy, greedy, "{what}");
                } else {
                    // Decided on the expected value (see the solver's docs): a maximiser of
                    // theta up to its rounding.
                    assert_maximisers(&s.greedy, &theta_next, nj, 1e-12);
                }
                assert!(
                    (s.final_delta - deltas.last().unwrap()).abs() < 1e-12,
                    "{what}"
                );
                let b = run(
                    &m,
                    &g,
                    &SolverConfig {
                        path: BackupPath::Block,
                        ..c
                    },
                );
                assert_eq!(b.path, BackupPath::Block);
                assert_eq!(b.sweeps.len(), deltas.len(), "{what}");
                assert_close(&b.v, &v, 1e-10);
                assert_maximisers(&b.greedy, &theta_next, nj, 1e-10);
                for path in [BackupPath::Generic, BackupPath::Block] {
                    let a = run(
                        &m,
                        &g,
                        &SolverConfig {
                            path,
                            sweep: SweepMode::Asynchronous,
                            ..c
                        },
                    );
                    assert!(a.converged());
                    assert!(max_diff(&a.v, &v) <= 2.0 * c.gamma / (1.0 - c.gamma) * c.xi);
                }
                // Terminal states matter here: not declaring them changes the fixed point.
                let plain = Cliff {
                    terminal: false,
                    clamp_first,
                    ..Cliff::new(dims, action_reward)
                };
                let p = run(&plain, &g, &c);
                assert!(max_diff(&p.v, &v) > 0.1, "{what}");
            }
        }
    }
}

/// On a model with blocks and terminal states, the block and generic backups, greedy actions
/// and decisions at any state agree; every kernel instance and thread count gives the same
/// bits.
#[test]
fn block_and_generic_agree_with_terminal_states() {
    for (absorbing, clamp_first) in [(false, false), (true, false), (false, true), (true, true)] {
        let m = Cliff {
            clamp_first,
            ..Cliff::<f64>::new(2, true)
        };
        let g = m.grid();
        let backup = Backup {
            gamma: 0.9,
            absorbing_goal: absorbing,
        };
        let block = Operator::new(&m, g.view(), backup, BackupPath::Block).unwrap();
        let generic = Operator::new(&m, g.view(), backup, BackupPath::Generic).unwrap();
        let v = values::<f64>(g.n_cores(), 5, -20.0, 30.0);
        assert_close(
            &block.apply(&v).unwrap(),
            &generic.apply(&v).unwrap(),
            1e-12,
        );
        assert_eq!(block.greedy(&v).unwrap(), generic.greedy(&v).unwrap());
        let (mut qb, mut qg) = (vec![0.0; 9], vec![0.0; 9]);
        for x in values::<f64>(2 * 40, 9, -0.5, 4.5).chunks(2) {
            block.q_values(&v, x, &mut qb).unwrap();
            generic.q_values(&v, x, &mut qg).unwrap();
            assert_close(&qb, &qg, 1e-12);
        }
        // At a core whose transitions all end, Q is the reward.
        let x = [4.0, 4.0];
        block.q_values(&v, &x, &mut qb).unwrap();
        for (u, q) in qb.iter().enumerate() {
            let mut a = [0.0; 2];
            fuzzyq_core::model::joint_actions(&m)
                .unwrap()
                .vector(u, &mut a)
                .unwrap();
            if a[1] > 0.0 {
                assert_eq!(*q, m.reward(&x, &a));
            }
        }
    }
    let m = Cliff::<f32>::new(2, true);
    let g = m.grid();
    let runs: Vec<Solution<f32>> = Kernel::ALL
        .iter()
        .copied()
        .filter(|k| k.is_available())
        .flat_map(|k| {
            let c = SolverConfig {
                kernel: Some(k),
                xi: 1e-4,
                ..config(BackupPath::Block, SweepMode::Synchronous)
            };
            [1, 3].map(|n| with_threads(n, || run(&m, &g, &c)))
        })
        .collect();
    for r in &runs[1..] {
        assert_eq!(r.v, runs[0].v);
        assert_eq!(r.greedy, runs[0].greedy);
        assert_eq!(r.sweeps.len(), runs[0].sweeps.len());
    }
}

/// A model that declares terminal states but never reaches one solves exactly as the model
/// without the declaration, on both paths (the block path keeps its fused kernels).
#[test]
fn declared_but_unreached_terminal_states_change_nothing() {
    let never = |x: &[f32]| x.iter().any(|v| v.abs() > 100.0);
    let (m, g) = medium_two_agent::<f32>();
    let (_, small) = small_one_agent::<f32>();
    let one = fuzzyq_tests::point_mass(1);
    for (plain, inner, grid, path) in [
        (&m, m.clone(), &g, BackupPath::Block),
        (&one, one.clone(), &small, BackupPath::Generic),
    ] {
        let c = config(path, SweepMode::Synchronous);
        let wrapped = WithTerminals {
            inner,
            terminal: never,
        };
        let (a, b) = (run(plain, grid, &c), run(&wrapped, grid, &c));
        assert_eq!(a.v, b.v, "{path:?}");
        assert_eq!(a.greedy, b.greedy);
        assert_eq!(a.sweeps.len(), b.sweeps.len());
    }
}

/// A tabulated model's terminal successors get no memberships: it solves like the model it
/// tabulates.
#[test]
fn tabulated_models_honour_terminal_states() {
    use fuzzyq_core::solver::TabulatedModel;
    let m = Cliff::<f64>::new(2, true);
    let g = m.grid();
    let view = g.view();
    let joint = fuzzyq_core::model::joint_actions(&m).unwrap();
    let (n, mj, e) = (g.n_cores(), joint.n_joint(), g.n_dims());
    let mut next = vec![0.0; n * mj * e];
    let mut rewards = vec![0.0; n * mj];
    let (mut x, mut u) = (vec![0.0; e], vec![0.0; 2]);
    for d in 0..n {
        view.core_state(d, &mut x).unwrap();
        for a in 0..mj {
            joint.vector(a, &mut u).unwrap();
            let i = d * mj + a;
            m.step(&x, &u, &mut next[i * e..(i + 1) * e]);
            rewards[i] = m.reward(&x, &u);
        }
    }
    let t = TabulatedModel::new(g.clone(), vec![(m.actions.clone(), 2)], next, rewards).unwrap();
    let c = config(BackupPath::Generic, SweepMode::Synchronous);
    let t = WithTerminals {
        inner: t,
        terminal: |x: &[f64]| x.iter().any(|&v| !(0.0..=4.0).contains(&v)),
    };
    let (a, b) = (run(&m, &g, &c), run(&t, &g, &c));
    assert_eq!(a.v, b.v);
    assert_eq!(a.greedy, b.greedy);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(12))]

    /// With terminal successors the backup is still a `gamma`-contraction on every path.
    #[test]
    fn terminal_backup_is_a_gamma_contraction(
        seed in any::<u64>(),
        gamma in 0.0..0.999f64,
        absorbing in any::<bool>(),
        generic in any::<bool>(),
        action_reward in any::<bool>(),
    ) {
        let m = Cliff::<f64>::new(2, action_reward);
        let g = m.grid();
        let path = if generic { BackupPath::Generic } else { BackupPath::Block };
        let op = Operator::new(&m, g.view(), Backup { gamma, absorbing_goal: absorbing }, path)
            .unwrap();
        let v1 = values::<f64>(g.n_cores(), seed, -100.0, 100.0);
        let v2 = values::<f64>(g.n_cores(), seed ^ 0xABCD, -100.0, 100.0);
        let lhs = max_diff(&op.apply(&v1).unwrap(), &op.apply(&v2).unwrap());
        let rhs = gamma * max_diff(&v1, &v2);
        prop_assert!(lhs <= rhs + 1e-9, "{lhs} > {rhs}");
    }
}

/// Stops a run after sweep `k`, keeping its state, continues from that state, and checks
/// that the result is the uninterrupted run's, bit for bit (values, greedy actions, every
/// sweep's change).
pub(crate) fn assert_resumes_bit_identically<T: Real, M: Model<T> + Sync>(
    m: &M,
    g: &Grid<T>,
    c: &SolverConfig,
) -> usize {
    let whole = run(m, g, c);
    let n = whole.sweeps.len();
    assert!(n >= 4, "{n} sweeps: too few to interrupt in between");
    let changes = |s: &Solution<T>| {
        s.sweeps
            .iter()
            .map(|r| {
                (
                    r.sweep,
                    r.delta,
                    r.delta_v.to_bits(),
                    r.extrapolated,
                    r.evaluation,
                )
            })
            .collect::<Vec<_>>()
    };
    for k in [1, 2, n / 2, n - 1] {
        let mut kept = None;
        let e = solve_from(m, g, c, None, |p, state| {
            if p.record.sweep == k {
                kept = state.cloned().map(SolverState::into_owned);
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        })
        .unwrap_err();
        assert_eq!(e, SolveError::Interrupted { sweeps: k });
        let state = kept.expect("a state before the last sweep");
        assert_eq!(state.sweeps(), k);
        let resumed = solve_from(m, g, c, Some(state), |_, _| ControlFlow::Continue(())).unwrap();
        assert!(
            resumed
                .v
                .iter()
                .zip(&whole.v)
                .all(|(a, b)| a.to_f64().to_bits() == b.to_f64().to_bits()),
            "V differs after resuming at sweep {k}"
        );
        assert_eq!(resumed.greedy, whole.greedy, "resumed at sweep {k}");
        assert_eq!(changes(&resumed), changes(&whole), "resumed at sweep {k}");
        assert_eq!(resumed.final_delta.to_bits(), whole.final_delta.to_bits());
        assert_eq!(resumed.stop, whole.stop);
    }
    n
}

#[test]
fn interrupted_runs_resume_bit_identically_in_every_scheme() {
    let (m, g) = medium_two_agent::<f32>();
    let sync = config(BackupPath::Block, SweepMode::Synchronous);
    let cases = [
        ("synchronous", sync),
        (
            "extrapolated",
            SolverConfig {
                extrapolate: true,
                ..sync
            },
        ),
        (
            "modified policy iteration",
            SolverConfig {
                extrapolate: true,
                evaluation_sweeps: 8,
                ..sync
            },
        ),
        (
            "asynchronous",
            config(BackupPath::Block, SweepMode::Asynchronous),
        ),
        (
            "sweep limit",
            SolverConfig {
                max_sweeps: 6,
                ..sync
            },
        ),
    ];
    for (name, c) in cases {
        let n = assert_resumes_bit_identically(&m, &g, &c);
        eprintln!("{name}: {n} sweeps");
    }
    let (m1, g1) = small_one_agent::<f64>();
    assert_resumes_bit_identically(
        &m1,
        &g1,
        &config(BackupPath::Generic, SweepMode::Synchronous),
    );
}

#[test]
fn a_state_that_does_not_fit_the_run_is_refused() {
    let (m, g) = medium_two_agent::<f32>();
    let sync = config(BackupPath::Block, SweepMode::Synchronous);
    let mut kept = None;
    let _ = solve_from(&m, &g, &sync, None, |p, s| {
        kept = s.cloned().map(SolverState::into_owned);
        if p.record.sweep == 3 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    });
    let state = kept.unwrap();
    let asynchronous = config(BackupPath::Block, SweepMode::Asynchronous);
    let mpi = SolverConfig {
        extrapolate: true,
        evaluation_sweeps: 8,
        ..sync
    };
    let short = SolverConfig {
        max_sweeps: 3,
        ..sync
    };
    let mut fewer = state.clone();
    fewer.v.to_mut().pop();
    let mut infinite = state.clone();
    infinite.v.to_mut()[0] = f32::INFINITY;
    for (c, s, needle) in [
        (&asynchronous, &state, "sweep mode"),
        (&mpi, &state, "scheme"),
        (&short, &state, "sweep limit"),
        (&sync, &fewer, "number of cores"),
        (&sync, &infinite, "not finite"),
    ] {
        let e =
            solve_from(&m, &g, c, Some(s.clone()), |_, _| ControlFlow::Continue(())).unwrap_err();
        assert!(matches!(e, SolveError::Resume { .. }), "{e}");
        assert!(e.to_string().contains(needle), "{e}");
    }
}

/// Regression (issue 49): `max_sweeps` counts every sweep under modified policy iteration,
/// evaluation sweeps too (it counted full backups only: `max_sweeps = 3` ran 13 sweeps), and
/// the last sweep allowed is a full backup, so that the run ends on MacQueen's bound. A run
/// continued from a saved state stops at the same limit.
#[test]
fn modified_policy_iteration_counts_every_sweep_against_the_limit() {
    let (m, g) = medium_two_agent::<f32>();
    let base = SolverConfig {
        xi: 1e-7,
        extrapolate: true,
        evaluation_sweeps: 5,
        ..config(BackupPath::Block, SweepMode::Synchronous)
    };
    let unlimited = run(&m, &g, &base);
    assert!(
        unlimited.evaluation_sweeps() > 0,
        "the run has evaluation sweeps"
    );
    for k in 1..=12 {
        let c = SolverConfig {
            max_sweeps: k,
            ..base
        };
        let s = run(&m, &g, &c);
        assert_eq!(s.sweeps.len(), k, "max_sweeps = {k}");
        assert_eq!(s.stop, Stop::SweepLimit);
        let last = s.sweeps.last().expect("a sweep");
        assert!(
            !last.evaluation,
            "max_sweeps = {k}: the last sweep is a full backup"
        );
        assert!(s.final_delta.is_finite() && s.final_delta > 0.0);
        // The sweeps before the last are those of the unlimited run.
        for (a, b) in s.sweeps[..k - 1].iter().zip(&unlimited.sweeps) {
            assert_eq!((a.sweep, a.evaluation), (b.sweep, b.evaluation));
        }
    }
}
