//! The slab entry points (`Operator::{input_slabs, apply_slabs, greedy_slabs,
//! evaluate_slabs}`): every shard of output slabs, computed from its halo of input slabs
//! alone, gives the bits of the full sweep; bad ranges, halos and buffers are refused.

use std::ops::{ControlFlow, Range};

use fuzzyq_core::solver::{BackupPath, Grid, Kernel, Operator, SolveError, SolverConfig, solve};
use fuzzyq_core::{Backup, Model, NamedOption, Real};
use fuzzyq_sim::model::pointmass::{PointMass, PointMassConfig};
use fuzzyq_tests::{grid, medium_two_agent, point_mass, with_threads};

use crate::solver::Cliff;

fn bits<T: Real>(x: &[T]) -> Vec<u64> {
    x.iter().map(|y| y.to_f64().to_bits()).collect()
}

/// `V` after a few sweeps (so greedy actions differ between cores).
fn some_v<T: Real, M: Model<T> + Sync>(m: &M, g: &Grid<T>) -> Vec<T> {
    let c = SolverConfig {
        max_sweeps: 6,
        ..SolverConfig::default()
    };
    solve(m, g, &c, |_| ControlFlow::Continue(()))
        .expect("solve")
        .v
}

/// The input slabs `halo` of the internal-order `vi`, one after another.
fn gather<T: Real>(vi: &[T], halo: &[u32], slab: usize) -> Vec<T> {
    halo.iter()
        .flat_map(|&c| vi[c as usize * slab..][..slab].iter().copied())
        .collect()
}

/// Every shard of widths 1, 2, 3 and all slabs, on every kernel instance and with 1 and 2
/// threads, against the full sweep in internal order. Returns the largest single-slab halo.
fn shards_match<T: Real, M: Model<T> + Sync>(
    m: &M,
    g: &Grid<T>,
    gamma: f64,
    absorbing: bool,
) -> usize {
    let backup = Backup {
        gamma: T::from_f64(gamma),
        absorbing_goal: absorbing,
    };
    let v = some_v(m, g);
    let mut widest = 0;
    for &k in Kernel::ALL.iter().filter(|k| k.is_available()) {
        let op = Operator::new(m, g.view(), backup, BackupPath::Block)
            .unwrap()
            .with_kernel(k)
            .unwrap();
        let layout = op.slab_layout().expect("block path");
        let (n, slab) = (layout.n_slabs, layout.slab_len);
        assert_eq!(n * slab, g.n_cores());
        let vi = op.to_internal_order(&v).unwrap();
        let full = op.to_internal_order(&op.apply(&v).unwrap()).unwrap();
        let greedy = op.to_internal_order(&op.greedy(&v).unwrap()).unwrap();
        let evaluates = op.evaluate_policy(&v, &op.greedy(&v).unwrap()).is_ok();
        for width in [1, 2, 3, n] {
            for start in (0..n).step_by(width) {
                let r: Range<usize> = start..(start + width).min(n);
                let halo = op.input_slabs(r.clone()).unwrap();
                if width == 1 {
                    widest = widest.max(halo.len());
                }
                let v_halo = gather(&vi, &halo, slab);
                let cores = r.start * slab..r.end * slab;
                for threads in [1, 2] {
                    let mut out = vec![T::ZERO; r.len() * slab];
                    with_threads(threads, || {
                        op.apply_slabs(r.clone(), &halo, &v_halo, &mut out)
                    })
                    .unwrap();
                    assert_eq!(bits(&out), bits(&full[cores.clone()]), "{} {r:?}", k.name());
                }
                let mut acts = vec![0u32; r.len() * slab];
                op.greedy_slabs(r.clone(), &halo, &v_halo, &mut acts)
                    .unwrap();
                assert_eq!(acts, greedy[cores.clone()], "{} {r:?}", k.name());
                let mut ev = vec![T::ZERO; r.len() * slab];
                let done = op.evaluate_slabs(r.clone(), &halo, &v_halo, &acts, &mut ev);
                if evaluates {
                    done.unwrap();
                    assert_eq!(bits(&ev), bits(&full[cores]), "{} {r:?}", k.name());
                } else {
                    assert_eq!(done, Err(SolveError::PolicyEvaluation));
                }
            }
        }
    }
    widest
}

#[test]
fn every_shard_computed_from_its_halo_gives_the_full_sweeps_bits() {
    // One agent on a finer grid: 21 slabs, each reading a few neighbours.
    let one = point_mass(1);
    let fine = grid::<f32>(
        1,
        &[-6.0, -3.0, -1.0, 0.0, 1.0, 3.0, 6.0],
        &[-3.0, 0.0, 3.0],
    );
    let widest = shards_match(&one, &fine, 0.96, false);
    assert!(widest < 21 / 2, "a slab's halo is {widest} of 21 slabs");
    // Two agents (4 blocks), in both precisions, and with an absorbing goal.
    let (two, g) = medium_two_agent::<f32>();
    shards_match(&two, &g, 0.96, false);
    let (two, g) = medium_two_agent::<f64>();
    shards_match(&two, &g, 0.96, false);
    shards_match(&two, &g, 0.9, true);
    // Three agents (6 blocks: the evaluation's stage before the last two is a middle one).
    let three = PointMass::new(PointMassConfig {
        agents: 3,
        force_levels: vec![-2.0, 2.0],
        ..PointMassConfig::default()
    })
    .unwrap();
    shards_match(
        &three,
        &grid::<f32>(3, &[-6.0, 0.0, 6.0], &[-3.0, 0.0, 3.0]),
        0.96,
        false,
    );
    // Terminal states: one block (a slab is one core) and two with action-dependent rewards.
    let cliff = Cliff::<f64>::new(1, false);
    shards_match(&cliff, &cliff.grid(), 0.96, false);
    let cliff = Cliff::<f64>::new(2, true);
    shards_match(&cliff, &cliff.grid(), 0.96, false);
}

#[test]
fn bad_slab_ranges_halos_and_buffers_are_refused() {
    let backup = Backup::discounted(0.96);
    let (m, g) = medium_two_agent::<f32>();
    let generic = Operator::new(&m, g.view(), backup, BackupPath::Generic).unwrap();
    assert!(generic.slab_layout().is_none());
    assert!(matches!(
        generic.input_slabs(0..1),
        Err(SolveError::Slabs { .. })
    ));
    let op = Operator::new(&m, g.view(), backup, BackupPath::Block).unwrap();
    let layout = op.slab_layout().unwrap();
    let (n, slab) = (layout.n_slabs, layout.slab_len);
    let vi = op.to_internal_order(&vec![1.0f32; g.n_cores()]).unwrap();
    let halo = op.input_slabs(1..2).unwrap();
    let v_halo = gather(&vi, &halo, slab);
    let mut out = vec![0.0f32; slab];
    let slabs_err = |e: Result<(), SolveError>| matches!(e, Err(SolveError::Slabs { .. }));
    let eval_err = |e: Result<(), SolveError>| matches!(e, Err(SolveError::Eval(_)));
    // Ranges: empty, reversed, past the end.
    assert!(op.input_slabs(2..2).is_err());
    assert!(op.input_slabs(n..n + 1).is_err());
    assert!(slabs_err(op.apply_slabs(
        0..n + 1,
        &halo,
        &v_halo,
        &mut out
    )));
    // Halos: missing a slab, unsorted, repeated, out of range.
    let all: Vec<u32> = (0..n as u32).collect();
    let v_all = gather(&vi, &all, slab);
    let short = &halo[1..];
    assert!(slabs_err(op.apply_slabs(
        1..2,
        short,
        &v_halo[slab..],
        &mut out
    )));
    let mut rev = all.clone();
    rev.swap(0, 1);
    assert!(slabs_err(op.apply_slabs(1..2, &rev, &v_all, &mut out)));
    let mut rep = all.clone();
    rep[1] = rep[0];
    assert!(slabs_err(op.apply_slabs(1..2, &rep, &v_all, &mut out)));
    let mut far = all.clone();
    *far.last_mut().unwrap() = n as u32;
    assert!(slabs_err(op.apply_slabs(1..2, &far, &v_all, &mut out)));
    // A superset halo is fine and gives the same bits.
    let mut sub = vec![0.0f32; slab];
    op.apply_slabs(1..2, &halo, &v_halo, &mut sub).unwrap();
    op.apply_slabs(1..2, &all, &v_all, &mut out).unwrap();
    assert_eq!(bits(&sub), bits(&out));
    // Buffers: the halo's values and the output.
    assert!(eval_err(op.apply_slabs(
        1..2,
        &halo,
        &v_halo[1..],
        &mut out
    )));
    assert!(eval_err(op.apply_slabs(
        1..2,
        &halo,
        &v_halo,
        &mut out[1..]
    )));
    let mut acts = vec![0u32; slab + 1];
    assert!(eval_err(op.greedy_slabs(1..2, &halo, &v_halo, &mut acts)));
    // Policies: wrong length, a joint action that does not exist.
    let bad = vec![op.joint().n_joint() as u32; slab];
    assert!(eval_err(op.evaluate_slabs(
        1..2,
        &halo,
        &v_halo,
        &bad,
        &mut out
    )));
    assert!(eval_err(op.evaluate_slabs(
        1..2,
        &halo,
        &v_halo,
        &bad[1..],
        &mut out
    )));
    // Orders: lengths checked, and a round trip is the identity.
    assert!(op.to_internal_order(&[0.0f32; 3]).is_err());
    let v: Vec<f32> = (0..g.n_cores()).map(|i| i as f32).collect();
    let back = op
        .to_grid_order(&op.to_internal_order(&v).unwrap())
        .unwrap();
    assert_eq!(back, v);
}
