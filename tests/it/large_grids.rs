//! Grids past 2^32 cores: the block path (and the GPU, `V` in parts) indexes cores in `usize`;
//! the solvers whose tables index them in 32 bits refuse such grids before allocating.

use std::ops::ControlFlow;

use fuzzyq_core::Backup;
use fuzzyq_core::solver::{BackupPath, Grid, Operator, SolverConfig};
use fuzzyq_sim::model::pointmass::{PointMass, PointMassConfig};

#[test]
fn grids_beyond_2_32_cores_build_and_only_the_32_bit_solvers_refuse_them() {
    // The paper's grid for three point masses: 45^6 cores. The block path indexes cores in
    // `usize` (the GPU runs it in parts of `V`); the generic path and Q-iteration index them
    // in 32 bits, and refuse it before allocating anything.
    let cfg = PointMassConfig {
        agents: 3,
        ..PointMassConfig::default()
    };
    let model = PointMass::new(cfg).unwrap();
    let pos = [-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0];
    let vel = [-3.0, -1.0, 0.0, 1.0, 3.0];
    let cores: Vec<Vec<f32>> = (0..3)
        .flat_map(|_| [pos.to_vec(), pos.to_vec(), vel.to_vec(), vel.to_vec()])
        .collect();
    let grid = Grid::new(cores).unwrap();
    assert_eq!(grid.view().n_cores(), 45usize.pow(6));
    let backup = Backup {
        gamma: 0.95f32,
        absorbing_goal: false,
    };
    let Err(e) = Operator::new(&model, grid.view(), backup, BackupPath::Generic) else {
        panic!("the generic path over 45^6 cores");
    };
    assert!(
        e.to_string()
            .contains("generic backup path would exceed 2^32"),
        "{e}"
    );
    let config = SolverConfig::default();
    let e = fuzzyq_core::solver::solve_q(&model, &grid, &config, |_, _| ControlFlow::Continue(()))
        .unwrap_err();
    assert!(
        e.to_string().contains("Q-iteration would exceed 2^32"),
        "{e}"
    );
}
