//! The Khepera experiment end to end: training over robot poses, the rapier plant, metrics.

use std::ops::ControlFlow;

use fuzzyq_core::q::PolicyKind;
use fuzzyq_core::solver::{BackupPath, Precision};
use fuzzyq_sim::PolicyArtifact;
use fuzzyq_sim::io::config::{EnvConfig, TrainConfig};
use fuzzyq_sim::io::policy_file::PolicyFile;
use fuzzyq_sim::model::EnvKind;
use fuzzyq_sim::model::arena::{Arena, Obstacle};
use fuzzyq_sim::model::khepera::random_starts;
use fuzzyq_sim::run::evaluate::khepera_starts;
use fuzzyq_sim::run::policy::Policy;
use fuzzyq_tests::{fqi_policy, khepera_run, point_mass_run};

fn khepera(agents: usize, position_cores: Vec<f64>, headings: usize) -> TrainConfig {
    let mut c = TrainConfig::default_for(EnvKind::Khepera).expect("default");
    if let EnvConfig::Khepera(k) = &mut c.env {
        k.agents = agents;
    }
    c.grid.position_cores = position_cores;
    c.grid.heading_divisions = Some(headings);
    c.validate().expect("valid");
    c
}

fn train(c: &TrainConfig) -> PolicyArtifact {
    fuzzyq_sim::train::train(c, |_| ControlFlow::Continue(())).expect("train")
}

#[test]
fn one_robot_trains_saves_and_arrives_on_the_plant() {
    let c = khepera(
        1,
        TrainConfig::default_for(EnvKind::Khepera)
            .unwrap()
            .grid
            .position_cores,
        16,
    );
    let a = train(&c);
    assert!(a.summary.converged);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("k.fzq");
    PolicyFile::Fqi(a).save(&path).unwrap();
    let policy = Policy::load(&path).unwrap();
    for start in [[-3.0, 2.0, 0.0], [4.0, -4.5, 2.5], [0.5, 5.0, -1.0]] {
        let (run, m) = khepera_run(&policy, &[start], 300, PolicyKind::Greedy, 1).unwrap();
        assert_eq!(run.poses.len(), 301);
        assert!(m.success, "from {start:?}: {m:?}");
        assert_eq!(m.collisions.total, 0);
        assert!(m.rollout.reach_time_s.is_some());
    }
}

#[test]
fn two_robot_smoke_run_is_deterministic() {
    let c = khepera(2, vec![-6.0, -2.0, -0.5, -0.1, 0.0, 0.1, 0.5, 2.0, 6.0], 8);
    let a = train(&c);
    let policy = fqi_policy(a);
    let (r1, _) = khepera_starts(&policy, 3, 5, 40, PolicyKind::Greedy).unwrap();
    let (r2, m2) = khepera_starts(&policy, 3, 5, 40, PolicyKind::Greedy).unwrap();
    assert_eq!(r1, r2);
    assert_eq!(m2.len(), 3);
    let starts = random_starts(
        match &c.env {
            EnvConfig::Khepera(k) => k,
            _ => unreachable!("a khepera config"),
        },
        3,
        5,
    )
    .unwrap();
    assert_eq!(starts.len(), 3);
    // Point-mass starts refuse a khepera policy with a clear error.
    let Err(e) = fuzzyq_sim::run::evaluate::point_mass_starts(
        &policy,
        &[vec![0.0; 8]],
        5,
        PolicyKind::Greedy,
    ) else {
        panic!("a khepera policy must be refused")
    };
    assert!(e.to_string().contains("khepera"), "{e}");
    // A robot's start of the wrong length (poses: 3 values per robot) is refused.
    for len in [1, 7, 8] {
        let Err(e) = point_mass_run(&policy, &vec![0.0; len], 5, PolicyKind::Greedy) else {
            panic!("a start of {len} values must be refused")
        };
        assert!(
            e.to_string()
                .contains(&format!("expected length 6, found {len}")),
            "{e}"
        );
    }
}

#[test]
fn block_and_generic_backups_agree_with_an_obstacle() {
    let mut c = khepera(2, vec![-6.0, -1.0, 0.0, 0.1, 1.0, 6.0], 4);
    if let EnvConfig::Khepera(k) = &mut c.env {
        k.arena = Arena {
            obstacles: vec![Obstacle::Box {
                center: [0.5, 0.5],
                half_extents: [0.4, 0.1],
                angle_deg: 30.0,
            }],
            ..Arena::default()
        };
    }
    c.solver.extrapolate = false;
    c.solver.max_sweeps = 30;
    c.solver.precision = Precision::F64;
    c.solver.backup = BackupPath::Block;
    let b = train(&c);
    c.solver.backup = BackupPath::Generic;
    let g = train(&c);
    let (
        fuzzyq_sim::io::policy_file::Values::F64(vb),
        fuzzyq_sim::io::policy_file::Values::F64(vg),
    ) = (&b.values, &g.values)
    else {
        panic!("f64 values")
    };
    let diff = vb
        .iter()
        .zip(vg)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    assert!(diff < 1e-9, "block and generic differ by {diff}");
    assert_eq!(b.summary.sweeps, g.summary.sweeps);
}
