//! End to end through the library: configuration, training, policy file, rollout.

use std::ops::ControlFlow;

use fuzzyq_core::q::PolicyKind;
use fuzzyq_core::solver::Precision;
use fuzzyq_sim::io::config::{EnvConfig, GridConfig, TrainConfig};
use fuzzyq_sim::io::policy_file::PolicyFile;
use fuzzyq_sim::model::pointmass::{Integrator, PointMass, PointMassConfig};
use fuzzyq_sim::paper::X0 as PAPER_X0;
use fuzzyq_sim::run::policy::Policy;
use fuzzyq_sim::{PolicyArtifact, SimError};
use fuzzyq_tests::{fqi_policy, point_mass_run};
use proptest::prelude::*;

/// The paper's task on a reduced grid (two agents, 3 x 3 x 3 x 3 cores each).
fn reduced() -> TrainConfig {
    TrainConfig {
        grid: GridConfig {
            position_cores: vec![-6.0, -0.5, 0.0, 0.5, 6.0],
            velocity_cores: vec![-3.0, 0.0, 3.0],
            heading_divisions: None,
            cores: None,
            membership: Default::default(),
        },
        ..TrainConfig::default()
    }
}

fn train(c: &TrainConfig) -> PolicyArtifact {
    fuzzyq_sim::train::train(c, |_| ControlFlow::Continue(())).expect("train")
}

#[test]
fn small_train_save_load_rollout() {
    let config = reduced();
    assert_eq!(config.n_cores(), 50_625);
    let artifact = train(&config);
    assert!(artifact.summary.converged);
    assert_eq!(artifact.summary.backup, "block");
    assert!(artifact.summary.final_delta <= 0.05);

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("policy.fzq");
    assert!(
        !artifact.summary.evaluation.is_empty(),
        "modified policy iteration ran"
    );
    let mut file = PolicyFile::Fqi(artifact);
    file.save(&path).unwrap();
    // Everything but the evaluation sweeps' record (known after training only) and the
    // timings (files keep none, so identical runs give identical files) round-trips.
    if let PolicyFile::Fqi(a) = &mut file {
        a.summary.evaluation.clear();
        a.summary.evaluation_seconds = 0.0;
        a.summary.seconds = 0.0;
        a.summary.sweep_seconds = 0.0;
        (a.summary.setup_seconds, a.summary.result_seconds) = (None, None);
    }
    assert_eq!(PolicyFile::load(&path).unwrap(), file);

    let policy = Policy::load(&path).unwrap();
    for kind in [PolicyKind::Greedy, PolicyKind::Interpolated] {
        let (t, m) = point_mass_run(&policy, &PAPER_X0, 75, kind).unwrap();
        assert_eq!(t.states.len(), 76);
        assert_eq!(t.actions.len(), 75);
        // The coarse grid still brings both agents from 7.2 m and 5.8 m to within 0.5 m.
        assert!(m.final_error_m.iter().all(|&e| e < 0.5), "{kind:?}: {m:?}");
        assert!(
            m.arrival_time_s.iter().any(Option::is_some),
            "{kind:?}: {m:?}"
        );
        assert!(m.value_x0 > 0.0);
        // Returns and rewards are consistent.
        let direct: f64 = t
            .rewards
            .iter()
            .enumerate()
            .map(|(k, r)| 0.96f64.powi(k as i32) * r)
            .sum();
        assert!((direct - m.discounted_return).abs() < 1e-9);
    }
}

#[test]
fn precision_f64_trains_the_same_policy() {
    let mut c = reduced();
    let a = train(&c);
    c.solver.precision = Precision::F64;
    let b = train(&c);
    assert_eq!(a.summary.sweeps, b.summary.sweeps);
    let policy = fqi_policy(b);
    let (_, m) = point_mass_run(&policy, &PAPER_X0, 75, PolicyKind::Greedy).unwrap();
    assert!(m.final_error_m.iter().all(|&e| e < 0.5), "{m:?}");
}

#[test]
fn rollout_rejects_bad_initial_states() {
    let mut c = reduced();
    c.solver.max_sweeps = 2;
    let policy = fqi_policy(train(&c));
    let err = |x0: &[f64]| {
        point_mass_run(&policy, x0, 5, PolicyKind::Greedy)
            .unwrap_err()
            .to_string()
    };
    assert!(err(&[0.0; 3]).contains("needs 8 values"));
    assert!(err(&[0.0, 0.0, 9.0, 0.0, 0.0, 0.0, 0.0, 0.0]).contains("x0[2] = 9"));
    assert!(err(&[f64::NAN; 8]).contains("x0[0]"));
}

#[test]
fn position_dependent_friction_trains_with_rk4() {
    let mut c = reduced();
    {
        let EnvConfig::Pointmass(p) = &mut c.env else {
            unreachable!("a point-mass config")
        };
        p.agents = 1;
        p.integrator = Integrator::Rk4;
        p.friction = fuzzyq_tests::friction_patch();
    }
    let a = train(&c);
    assert!(a.summary.converged);
    assert_eq!(a.summary.backup, "block");
}

#[test]
fn invalid_config_is_a_typed_error() {
    let mut c = reduced();
    c.solver.gamma = 1.5;
    let e = fuzzyq_sim::train::train(&c, |_| ControlFlow::Continue(())).unwrap_err();
    assert!(matches!(e, SimError::Config(_)));
    assert_eq!(e.to_string(), "solver.gamma: must be in [0, 1), got 1.5");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// The closed-form step matches fine RK4 for any state and force.
    #[test]
    fn exact_step_matches_fine_rk4(
        x in prop::collection::vec(-1.0..1.0f64, 4),
        u in prop::collection::vec(-2.0..2.0f64, 2),
        eta in 0.0..3.0f64,
        mass in 0.1..2.0f64,
    ) {
        let base = PointMassConfig {
            agents: 1,
            mass,
            friction: fuzzyq_sim::model::pointmass::FrictionConfig::Constant { eta },
            ..PointMassConfig::default()
        };
        let exact = PointMass::new(base.clone()).unwrap();
        let rk = PointMass::new(PointMassConfig {
            integrator: Integrator::Rk4,
            rk4_substeps: 200,
            ..base
        })
        .unwrap();
        // Scale into the state box.
        let x = [5.0 * x[0], 5.0 * x[1], 2.5 * x[2], 2.5 * x[3]];
        let (mut a, mut b) = ([0.0; 4], [0.0; 4]);
        exact.step_f64(&x, &u, &mut a);
        rk.step_f64(&x, &u, &mut b);
        for (p, q) in a.iter().zip(&b) {
            prop_assert!((p - q).abs() < 1e-8, "{a:?} vs {b:?}");
        }
    }
}

#[test]
fn every_example_configuration_is_valid() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples");
    let mut seen = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "toml") {
            let text = std::fs::read_to_string(&path).unwrap();
            let c = TrainConfig::from_toml(&text).unwrap_or_else(|e| panic!("{path:?}: {e}"));
            c.validate().unwrap_or_else(|e| panic!("{path:?}: {e}"));
            seen += 1;
        }
    }
    assert!(seen >= 3, "{seen} configurations in {dir:?}");
    // The sizes scripts/gpu-check.sh and the file's header state.
    let text = std::fs::read_to_string(dir.join("three-point-masses.toml")).unwrap();
    let three = TrainConfig::from_toml(&text).unwrap();
    assert_eq!(three.n_cores(), 21usize.pow(6));
    assert_eq!(three.n_joint_actions(), 729);
}
