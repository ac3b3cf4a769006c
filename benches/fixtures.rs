//! Shared fixtures of the benchmarks: the paper's grid and model, reduced grids, and
//! deterministic pseudo-random tables.
#![allow(missing_docs)] // benchmark support

use fuzzyq_core::solver::Grid;
use fuzzyq_core::{Backup, Real};
use fuzzyq_sim::PointMass;
use fuzzyq_sim::io::config::TrainConfig;
use fuzzyq_sim::model::{EnvKind, EnvModel};

/// The paper's initial state.
pub const X0: [f64; 8] = [-4.0, -6.0, -2.0, 2.0, 5.0, 3.0, 2.0, -1.0];

/// The paper's two-agent model.
#[must_use]
pub fn model() -> PointMass {
    PointMass::paper()
}

/// The paper's grid (4,100,625 cores).
#[must_use]
pub fn paper_grid<T: Real>() -> Grid<T> {
    TrainConfig::default().grid().expect("paper grid")
}

/// The default problems of the benches over a whole grid on the block path, by name: the
/// paper's point masses (`paper`) and Khepera robots (`khepera`), each its model and grid.
#[must_use]
pub fn default_problems() -> Vec<(&'static str, EnvModel, Grid<f32>)> {
    [("paper", EnvKind::Pointmass), ("khepera", EnvKind::Khepera)]
        .into_iter()
        .map(|(name, env)| {
            let config = TrainConfig::default_for(env).expect("default config");
            let model = config.build_model().expect("default model");
            (name, model, config.grid().expect("default grid"))
        })
        .collect()
}

/// The backup of [`default_problems`]' benches.
pub const BACKUP: Backup<f32> = Backup {
    gamma: 0.9,
    absorbing_goal: false,
};

/// A reduced two-agent grid: 5 position and 3 velocity cores (50,625 cores).
#[must_use]
pub fn reduced_grid<T: Real>() -> Grid<T> {
    let mut c = TrainConfig::default();
    c.grid.position_cores = vec![-6.0, -0.5, 0.0, 0.5, 6.0];
    c.grid.velocity_cores = vec![-3.0, 0.0, 3.0];
    c.grid().expect("reduced grid")
}

/// `n` deterministic pseudo-random values in `[0, scale)`.
#[must_use]
pub fn values<T: Real>(n: usize, scale: f64) -> Vec<T> {
    let mut s: u64 = 0x2545_F491_4F6C_DD1D;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            T::from_f64(scale * ((s >> 11) as f64 / (1u64 << 53) as f64))
        })
        .collect()
}

/// The state in precision `T`.
#[must_use]
pub fn x0<T: Real>() -> Vec<T> {
    X0.iter().map(|&v| T::from_f64(v)).collect()
}

/// `V` after 40 extrapolated sweeps on `grid`: a realistic value function (a random one defeats
/// the last stage's pruning, which real value functions allow).
#[must_use]
pub fn realistic_v(grid: &Grid<f32>) -> Vec<f32> {
    let config = fuzzyq_core::solver::SolverConfig {
        max_sweeps: 40,
        extrapolate: true,
        ..Default::default()
    };
    fuzzyq_core::solver::solve(&model(), grid, &config, |_| {
        std::ops::ControlFlow::Continue(())
    })
    .expect("solve")
    .v
}
