//! One decision at a time on pre-drawn uniformly random states: the greedy policy
//! (`Operator::q_values` + argmax, eq 7) and the interpolated policy (eq 22), on the paper's
//! grid in both precisions, on the one-agent point mass and on a classic benchmark (generic
//! path). `V` and the per-core greedy table are seeded pseudo-random: solving is not needed
//! for timing, and a random `V` gives no decision an easy case.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{
    BenchmarkGroup, Criterion, criterion_group, criterion_main, measurement::WallTime,
};
use fuzzyq_benches::{paper_grid, values};
use fuzzyq_core::model::joint_actions;
use fuzzyq_core::solver::{BackupPath, Grid, Operator};
use fuzzyq_core::{Backup, Model, Real, q};
use fuzzyq_sim::io::config::EnvConfig;
use fuzzyq_sim::model::classic::{Classic, DcMotor, Dynamics, preset};
use fuzzyq_sim::{PointMass, PointMassConfig, TrainConfig};

/// Number of pre-drawn states each benchmark cycles through.
const STATES: usize = 1000;

/// `n` states drawn uniformly from the grid's box (seeded).
fn random_states<T: Real>(grid: &Grid<T>, n: usize, seed: u64) -> Vec<Vec<T>> {
    let mut s = seed | 1;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        (s >> 11) as f64 / (1u64 << 53) as f64
    };
    (0..n)
        .map(|_| {
            grid.cores()
                .iter()
                .map(|c| {
                    let (lo, hi) = (c[0].to_f64(), c[c.len() - 1].to_f64());
                    T::from_f64(lo + (hi - lo) * next())
                })
                .collect()
        })
        .collect()
}

/// Greedy (`q_values` + argmax) and interpolated decisions of `model` on `grid`.
fn bench_model<T: Real, M: Model<T> + Sync>(
    g: &mut BenchmarkGroup<'_, WallTime>,
    name: &str,
    model: &M,
    grid: &Grid<T>,
    path: BackupPath,
) {
    let view = grid.view();
    let backup = Backup {
        gamma: T::from_f64(0.96),
        absorbing_goal: false,
    };
    let op = Operator::new(model, view, backup, path).unwrap();
    let joint = joint_actions(model).unwrap();
    let m = joint.n_joint();
    let v = values::<T>(grid.n_cores(), 100.0);
    let greedy: Vec<u32> = values::<f64>(grid.n_cores(), m as f64)
        .into_iter()
        .map(|u| (u as u32).min(m as u32 - 1))
        .collect();
    let states = random_states(grid, STATES, 0x9E37_79B9_7F4A_7C15);
    let mut qx = vec![T::ZERO; m];
    let mut u = vec![T::ZERO; joint.dim()];
    let mut i = 0usize;
    g.bench_function(format!("greedy_{name}"), |b| {
        b.iter(|| {
            i = (i + 1) % STATES;
            op.q_values(&v, black_box(&states[i]), &mut qx).unwrap();
            black_box(q::argmax(&qx))
        })
    });
    g.bench_function(format!("interpolated_{name}"), |b| {
        b.iter(|| {
            i = (i + 1) % STATES;
            q::interpolated_action(&view, &joint, &greedy, black_box(&states[i]), &mut u).unwrap();
            black_box(u[0])
        })
    });
}

fn decisions(c: &mut Criterion) {
    let mut g = c.benchmark_group("decisions");
    {
        let model = PointMass::paper();
        let grid = paper_grid::<f32>();
        bench_model(&mut g, "paper_f32", &model, &grid, BackupPath::Block);
        let grid = paper_grid::<f64>();
        bench_model(&mut g, "paper_f64", &model, &grid, BackupPath::Block);
    }
    {
        let env = PointMassConfig {
            agents: 1,
            ..PointMassConfig::default()
        };
        let model = PointMass::new(env.clone()).unwrap();
        let config = TrainConfig {
            env: EnvConfig::Pointmass(env),
            ..TrainConfig::default()
        };
        let grid = config.grid::<f32>().unwrap();
        bench_model(&mut g, "one_agent_f32", &model, &grid, BackupPath::Block);
    }
    {
        let p = preset::<DcMotor>("fine").unwrap();
        let model =
            Classic::<DcMotor>::for_preset(<DcMotor as Dynamics>::Config::default(), &p).unwrap();
        let grid = p.grid::<f64>().unwrap();
        bench_model(&mut g, "dcmotor_fine_f64", &model, &grid, BackupPath::Auto);
    }
    g.finish();
}

criterion_group!(benches, decisions);
criterion_main!(benches);
