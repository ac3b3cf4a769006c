//! Stochastic block tables given by a model (the learned fuzzy model): the block backup reads
//! them, reduces to the stepping backup without noise, and stays a gamma-contraction with it.

use fuzzyq_core::solver::{BackupPath, Operator, SolveError};
use fuzzyq_core::{Backup, Membership};
use fuzzyq_sim::learn::fit::{FitConfig, fit};
use fuzzyq_sim::learn::samples::{Collection, Exploration, collect};
use fuzzyq_sim::learn::tasks::pointmass::default_starts;
use fuzzyq_sim::model::learned::LearnedModel;
use fuzzyq_sim::model::pointmass::{PointMass, PointMassConfig};
use fuzzyq_sim::model::{EnvModel, F64Model};
use fuzzyq_tests::{assert_close, grid};

const POS: [f64; 5] = [-6.0, -1.0, 0.0, 1.0, 6.0];
const VEL: [f64; 3] = [-3.0, 0.0, 3.0];

/// Two point masses with velocity noise `sigma`, and the model learned from 4000 of their
/// transitions on the grid of `POS` and `VEL`.
fn learned(sigma: f64) -> (EnvModel, LearnedModel) {
    learned_with(sigma, Membership::Triangular)
}

/// [`learned`] with the rows' memberships taken with `membership`.
fn learned_with(sigma: f64, membership: Membership) -> (EnvModel, LearnedModel) {
    let task = EnvModel::PointMass(
        PointMass::new(PointMassConfig {
            velocity_noise: sigma,
            ..PointMassConfig::default()
        })
        .unwrap(),
    );
    let starts = default_starts();
    let collection = Collection {
        samples: 4000,
        episode_steps: 50,
        seed: 11,
    };
    let data = collect(
        &task,
        &collection,
        |rng, x| starts.draw(rng, x),
        &mut Exploration::Random,
    )
    .unwrap();
    let cores: Vec<Vec<f64>> = (0..2)
        .flat_map(|_| [POS.to_vec(), POS.to_vec(), VEL.to_vec(), VEL.to_vec()])
        .collect();
    let blocks = F64Model::blocks(&task).to_vec();
    let config = FitConfig {
        membership,
        ..FitConfig::default()
    };
    let (tables, _) = fit(&task, &cores, &blocks, &data, &config).unwrap();
    let model = LearnedModel::new(task.clone(), tables).unwrap();
    (task, model)
}

fn values(n: usize, seed: u64) -> Vec<f64> {
    crate::solver::values(n, seed, -50.0, 120.0)
}

fn max_abs_diff(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
}

#[test]
fn given_rows_without_noise_reduce_to_the_stepping_backup() {
    let (task, model) = learned(0.0);
    let g = grid::<f64>(2, &POS, &VEL);
    let backup = Backup::discounted(0.96);
    let stepping = Operator::new(&task, g.view(), backup, BackupPath::Block).unwrap();
    let given = Operator::new(&model, g.view(), backup, BackupPath::Auto).unwrap();
    assert_eq!(given.path(), BackupPath::Block);
    // The learned rows match the model's to about 1e-11 (rows at the ranges' edges are fitted
    // on wide windows), on values of up to 170.
    for seed in 0..3 {
        let v = values(g.n_cores(), seed);
        assert_close(
            &given.apply(&v).unwrap(),
            &stepping.apply(&v).unwrap(),
            1e-8,
        );
    }
    // Only the block path reads given rows.
    let e = Operator::new(&model, g.view(), backup, BackupPath::Generic).err();
    assert!(matches!(e, Some(SolveError::BlockRowsOnly { .. })), "{e:?}");
}

#[test]
fn stochastic_backups_are_gamma_contractions() {
    let (_, model) = learned(0.2);
    let g = grid::<f64>(2, &POS, &VEL);
    let gamma = 0.9;
    let op = Operator::new(
        &model,
        g.view(),
        Backup::discounted(gamma),
        BackupPath::Block,
    )
    .unwrap();
    for seed in 0..4 {
        let (v1, v2) = (values(g.n_cores(), seed), values(g.n_cores(), seed + 100));
        let (t1, t2) = (op.apply(&v1).unwrap(), op.apply(&v2).unwrap());
        let (dt, dv) = (max_abs_diff(&t1, &t2), max_abs_diff(&v1, &v2));
        assert!(dt <= gamma * dv * (1.0 + 1e-9), "{dt} > {gamma} * {dv}");
        // A constant shift moves the backup by exactly gamma times it (rows sum to 1).
        let shifted: Vec<f64> = v1.iter().map(|x| x + 10.0).collect();
        let ts = op.apply(&shifted).unwrap();
        for (a, b) in ts.iter().zip(&t1) {
            assert!((a - b - gamma * 10.0).abs() < 1e-6, "{a} - {b}");
        }
    }
}

#[test]
fn crisp_rows_reduce_to_the_stepping_backup_on_a_crisp_grid() {
    let (task, model) = learned_with(0.0, Membership::Crisp);
    let g = grid::<f64>(2, &POS, &VEL).with_membership(Membership::Crisp);
    let backup = Backup::discounted(0.96);
    let stepping = Operator::new(&task, g.view(), backup, BackupPath::Block).unwrap();
    let given = Operator::new(&model, g.view(), backup, BackupPath::Block).unwrap();
    let v = values(g.n_cores(), 5);
    assert_close(
        &given.apply(&v).unwrap(),
        &stepping.apply(&v).unwrap(),
        1e-9,
    );
}

/// Rounds of collection: each further round adds as many transitions, collected
/// epsilon-greedily with the policy so far, refits and solves; the run is deterministic.
#[test]
fn further_rounds_refit_on_everything_collected_and_are_reproducible() {
    use fuzzyq_sim::io::config::{EnvConfig, TrainConfig};
    use fuzzyq_sim::train::{ModelLearning, train_learned};
    use std::ops::ControlFlow;

    let mut config = TrainConfig::default();
    if let EnvConfig::Pointmass(p) = &mut config.env {
        p.agents = 1;
        p.velocity_noise = 0.05;
    }
    config.grid.position_cores = POS.to_vec();
    config.grid.velocity_cores = VEL.to_vec();
    let mut learning = ModelLearning::new(300, 4);
    learning.rounds = 3;
    learning.epsilon = 0.2;
    let go = |l: &ModelLearning| train_learned(&config, l, |_| ControlFlow::Continue(())).unwrap();
    let a = go(&learning);
    let b = go(&learning);
    assert_eq!(a.artifact.values, b.artifact.values);
    assert_eq!(a.artifact.learned, b.artifact.learned);
    let counts: Vec<usize> = a.rounds.iter().map(|r| r.transitions).collect();
    assert_eq!(counts, [300, 600, 900]);
    assert_eq!(a.fit.samples, 900);
    // The first round is the one-round run; the later ones fit different data.
    learning.rounds = 1;
    let one = go(&learning);
    assert_eq!(one.rounds.len(), 1);
    assert_eq!(one.rounds[0].transitions, 300);
    assert_ne!(one.artifact.learned, a.artifact.learned);
    learning.rounds = 0;
    let e = train_learned(&config, &learning, |_| ControlFlow::Continue(()))
        .unwrap_err()
        .to_string();
    assert!(e.contains("rounds"), "{e}");
}

/// A learned model is known on its own grid only, so it takes no coarse start: the same run as
/// without one, bit for bit.
#[test]
fn learned_models_take_no_coarse_start() {
    use fuzzyq_core::solver::{Grid, SolverConfig, solve};
    let (_, model) = learned(0.0);
    let g: Grid<f64> = grid(2, &POS, &VEL);
    assert!(g.coarsened().is_some());
    let c = SolverConfig {
        xi: 0.5,
        extrapolate: true,
        evaluation_sweeps: 5,
        ..SolverConfig::default()
    };
    let go = |coarse_start| {
        solve(&model, &g, &SolverConfig { coarse_start, ..c }, |_| {
            std::ops::ControlFlow::Continue(())
        })
        .unwrap()
    };
    let (with, without) = (go(true), go(false));
    assert!(with.coarse.is_none());
    assert_eq!(with.v, without.v);
    assert_eq!(with.greedy, without.greedy);
}
