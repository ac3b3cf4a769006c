//! The coarse start ([`SolverConfig::coarse_start`]): the same error bound as a start from
//! `V = 0`, the coarse grid's run really used, the same bits for any thread count and after a
//! resume, and ignored where it does not apply.

use std::ops::ControlFlow;

use fuzzyq_core::solver::{Grid, Scheme, Solution, SolverConfig, SweepMode, solve};
use fuzzyq_core::{Model, Real};
use fuzzyq_tests::{
    assert_same_bits, block_operator, grid, max_diff, medium_two_agent, point_mass, with_threads,
};

/// One point mass on a grid fine enough to coarsen: 7 position and 5 velocity cores per axis
/// (1,225 cores), whose coarse grid has 5 and 3 (225 cores).
fn fine_one_agent<T: Real>() -> (fuzzyq_sim::model::pointmass::PointMass, Grid<T>) {
    (
        point_mass(1),
        grid(
            1,
            &[-6.0, -3.0, -1.0, 0.0, 1.0, 3.0, 6.0],
            &[-3.0, -1.0, 0.0, 1.0, 3.0],
        ),
    )
}

fn run<T: Real, M: Model<T> + Sync>(m: &M, g: &Grid<T>, c: &SolverConfig) -> Solution<T> {
    solve(m, g, c, |_| ControlFlow::Continue(())).expect("solve")
}

fn mpi(xi: f64, coarse_start: bool) -> SolverConfig {
    SolverConfig {
        xi,
        extrapolate: true,
        evaluation_sweeps: 5,
        coarse_start,
        ..SolverConfig::default()
    }
}

/// Against a tightly converged reference, a run from the coarse start stops within its own
/// a-posteriori bound, which is within `gamma xi / (1 - gamma)`, with its greedy actions those
/// of the returned `V`; and it did start from the coarse grid's `V`.
#[test]
fn coarse_start_stops_within_the_same_bound() {
    let (m, g) = fine_one_agent::<f64>();
    let coarse = g.coarsened().expect("a grid that coarsens");
    assert_eq!(coarse.n_cores(), 225);
    let reference = run(
        &m,
        &g,
        &SolverConfig {
            xi: 1e-9,
            extrapolate: true,
            ..SolverConfig::default()
        },
    );
    let gamma = 0.96;
    let op = block_operator(&m, &g, gamma);
    for xi in [0.5, 0.05, 0.005] {
        let s = run(&m, &g, &mpi(xi, true));
        assert_eq!(s.scheme, Scheme::ModifiedPolicy);
        let c = s.coarse.expect("a coarse start");
        assert_eq!(c.cores, 225);
        assert!(c.sweeps > 0 && c.seconds >= 0.0);
        assert!(s.converged() && s.final_delta <= xi, "xi {xi}");
        let err = max_diff(&s.v, &reference.v);
        let bound = s.error_bound(gamma);
        assert!(err <= bound + 1e-9, "xi {xi}: error {err} > bound {bound}");
        assert!(bound <= gamma / (1.0 - gamma) * xi);
        assert_eq!(op.greedy(&s.v).unwrap(), s.greedy, "xi {xi}");
        // From V = 0 the first full backup's change is the reward bound; from the coarse
        // start it is not.
        let plain = run(&m, &g, &mpi(xi, false));
        assert!(plain.coarse.is_none());
        assert_eq!(plain.sweeps[0].delta_v, plain.reward_bound);
        assert_ne!(s.sweeps[0].delta_v, s.reward_bound, "xi {xi}");
        // The first full backup's policy is the coarse `V`'s, worth evaluating at once (from
        // V = 0 every action ties, and evaluation waits for the second).
        assert!(s.sweeps[1].evaluation, "xi {xi}");
        assert!(!plain.sweeps[1].evaluation);
    }
}

/// Value iteration, a grid with nothing to drop, and the coarse grid's own run take no coarse
/// start: `V = 0` as before, bit for bit.
#[test]
fn coarse_start_is_ignored_where_it_does_not_apply() {
    let (m, g) = fine_one_agent::<f32>();
    let value = SolverConfig {
        evaluation_sweeps: 0,
        ..mpi(0.05, true)
    };
    let s = run(&m, &g, &value);
    assert_eq!(s.scheme, Scheme::Value);
    assert!(s.coarse.is_none());
    let without = run(
        &m,
        &g,
        &SolverConfig {
            coarse_start: false,
            ..value
        },
    );
    assert_eq!(s.v, without.v);
    let (m2, g2) = medium_two_agent::<f32>();
    assert!(g2.coarsened().is_none(), "3 cores per variable");
    let a = run(&m2, &g2, &mpi(0.05, true));
    let b = run(&m2, &g2, &mpi(0.05, false));
    assert!(a.coarse.is_none());
    assert_eq!((a.v, a.greedy), (b.v, b.greedy));
}

/// The coarse start gives the same bits on 1, 2 and 3 threads.
#[test]
fn coarse_start_does_not_depend_on_thread_count() {
    let (m, g) = fine_one_agent::<f32>();
    let c = SolverConfig {
        sweep: SweepMode::Synchronous,
        ..mpi(0.01, true)
    };
    let runs: Vec<Solution<f32>> = [1, 2, 3]
        .into_iter()
        .map(|n| with_threads(n, || run(&m, &g, &c)))
        .collect();
    assert!(runs[0].coarse.is_some());
    assert_same_bits(&runs);
}

/// A run from the coarse start, stopped after any sweep and continued from its state, ends as
/// the run that was never stopped, bit for bit (the state holds its `V`; no second coarse
/// run).
#[test]
fn coarse_start_runs_resume_bit_identically() {
    let (m, g) = fine_one_agent::<f32>();
    let n = crate::solver::assert_resumes_bit_identically(&m, &g, &mpi(0.01, true));
    assert!(n >= 4);
}
