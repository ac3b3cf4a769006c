//! One decision at a time on pre-drawn uniformly random states: the greedy policy
//! (`Operator::q_values` + argmax, eq 7) and the interpolated policy (eq 22), on the paper's
//! grid in both precisions, on the one-agent point mass and on a classic benchmark (generic
//! path). `V` and the per-core greedy table are seeded pseudo-random: solving is not needed
//! for timing, and a random `V` gives no decision an easy case.
//!
//! Group `view`: the same decisions as a `no_std` controller takes them from an exported
//! policy (`fuzzyq_core::view::PolicyView`, no allocation), on trained policies: the paper's
//! point masses (`fuzzyq export --greedy`: greedy from the decision tables), the DC motor and
//! the pendulum (`toolbox-demo`; greedy from `V` and the model). The exported sizes are
//! printed. The paper's greedy decision is timed on a plain buffer (4 KiB pages) and as
//! `fuzzyq_sim::io::export::ExportedBytes` loads it (transparent huge pages on Linux).
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{
    BenchmarkGroup, Criterion, criterion_group, criterion_main, measurement::WallTime,
};
use fuzzyq_benches::{paper_grid, values};
use fuzzyq_core::model::joint_actions;
use fuzzyq_core::solver::{BackupPath, Grid, Operator};
use fuzzyq_core::view::{PolicyView, ViewReal};
use fuzzyq_core::{Backup, Model, Real, q};
use fuzzyq_sim::PolicyArtifact;
use fuzzyq_sim::io::config::EnvConfig;
use fuzzyq_sim::io::export::{ExportOptions, ExportedBytes, export_bytes};
use fuzzyq_sim::io::policy_file::Values;
use fuzzyq_sim::model::EnvKind;
use fuzzyq_sim::model::classic::{Benchmark, Classic, DcMotor, preset};
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
    let backup = Backup::discounted(T::from_f64(0.96));
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
            Classic::<DcMotor>::for_preset(<DcMotor as Benchmark>::Config::default(), &p).unwrap();
        let grid = p.grid::<f64>().unwrap();
        bench_model(&mut g, "dcmotor_fine_f64", &model, &grid, BackupPath::Auto);
    }
    g.finish();
}

/// `bytes` at an 8-byte boundary of a fresh buffer: (buffer, offset).
fn placed(bytes: &[u8]) -> (Vec<u8>, usize) {
    let mut buf = vec![0u8; bytes.len() + 8];
    let at = buf.as_ptr().align_offset(8);
    buf[at..at + bytes.len()].copy_from_slice(bytes);
    (buf, at)
}

fn trained(config: &TrainConfig) -> PolicyArtifact {
    fuzzyq_sim::train::train(config, |_| std::ops::ControlFlow::Continue(())).unwrap()
}

/// Decisions from the export of `artifact` (with the decision tables if `tables`, else greedy
/// from the model).
fn bench_view<T: ViewReal>(
    g: &mut BenchmarkGroup<'_, WallTime>,
    name: &str,
    artifact: &PolicyArtifact,
    tables: bool,
) where
    fuzzyq_sim::model::EnvModel: Model<T>,
{
    let options = ExportOptions {
        values: true,
        decisions: tables,
    };
    let bytes = export_bytes(artifact, options).unwrap();
    let lean = export_bytes(
        artifact,
        ExportOptions {
            values: false,
            decisions: false,
        },
    )
    .unwrap();
    let (buf, at) = placed(&bytes);
    let view = PolicyView::<T>::parse(&buf[at..at + bytes.len()]).unwrap();
    println!(
        "view/{name}: {} cores, exported {} bytes{}, {} bytes without V",
        view.grid().n_cores(),
        bytes.len(),
        if tables {
            format!(
                " with the decision tables (scratch {} KiB)",
                view.decision_scratch_len().unwrap() * 8 / 1024
            )
        } else {
            String::new()
        },
        lean.len()
    );
    let grid = artifact.config.grid::<T>().unwrap();
    let states = random_states(&grid, STATES, 0x9E37_79B9_7F4A_7C15);
    let (m, d) = (view.joint().n_joint(), view.joint().dim());
    let (mut q, mut u) = (vec![T::ZERO; m], vec![T::ZERO; d]);
    let mut i = 0usize;
    // With decision tables, on 4 KiB pages (a plain buffer) and as a controller with std
    // loads the export (`ExportedBytes`: advised into transparent huge pages).
    let loaded = ExportedBytes::copy_of(&bytes).unwrap();
    let huge = PolicyView::<T>::parse(loaded.bytes()).unwrap();
    let views = if tables {
        vec![("_small_pages", &view), ("", &huge)]
    } else {
        vec![("", &view)]
    };
    let mut scratch = view.decision_scratch_len().map(|n| vec![0u64; n]);
    for (suffix, v) in views {
        g.bench_function(format!("interpolated_{name}{suffix}"), |b| {
            b.iter(|| {
                i = (i + 1) % STATES;
                v.interpolated_action(black_box(&states[i]), &mut u)
                    .unwrap();
                black_box(u[0])
            })
        });
        if let Some(scratch) = scratch.as_mut() {
            g.bench_function(format!("greedy_{name}{suffix}"), |b| {
                b.iter(|| {
                    i = (i + 1) % STATES;
                    black_box(
                        v.greedy_action(black_box(&states[i]), scratch, &mut q, &mut u)
                            .unwrap(),
                    )
                })
            });
        }
    }
    if let Some(mut scratch) = scratch {
        g.bench_function(format!("interpolated_{name}_same_state"), |b| {
            b.iter(|| {
                huge.interpolated_action(black_box(&states[7]), &mut u)
                    .unwrap();
                black_box(u[0])
            })
        });
        // One state again and again: `V`'s lines stay in the caches, so this is the decision's
        // arithmetic without the memory latency the random states pay.
        g.bench_function(format!("greedy_{name}_same_state"), |b| {
            b.iter(|| {
                black_box(
                    huge.greedy_action(black_box(&states[7]), &mut scratch, &mut q, &mut u)
                        .unwrap(),
                )
            })
        });
        let view = huge;
        // In a control loop: the states of the greedy closed loop from the paper's start
        // (consecutive states are close, so their boxes of V overlap in the caches).
        let model = artifact.config.build_model().unwrap();
        let mut x: Vec<f64> = fuzzyq_sim::paper::X0.to_vec();
        let mut loop_states = Vec::new();
        let mut next = vec![0.0; x.len()];
        for _ in 0..75 {
            let xt: Vec<T> = x.iter().map(|&v| T::from_f64(v)).collect();
            view.greedy_action(&xt, &mut scratch, &mut q, &mut u)
                .unwrap();
            let uf: Vec<f64> = u.iter().map(|v| v.to_f64()).collect();
            Model::<f64>::step(&model, &x, &uf, &mut next);
            std::mem::swap(&mut x, &mut next);
            loop_states.push(xt);
        }
        let mut k = 0usize;
        g.bench_function(format!("greedy_{name}_closed_loop"), |b| {
            b.iter(|| {
                k = (k + 1) % loop_states.len();
                black_box(
                    view.greedy_action(black_box(&loop_states[k]), &mut scratch, &mut q, &mut u)
                        .unwrap(),
                )
            })
        });
    } else {
        let model = artifact.config.build_model().unwrap();
        let backup = Backup {
            gamma: T::from_f64(artifact.config.solver.gamma),
            absorbing_goal: artifact.config.solver.absorbing_goal,
        };
        let mut scratch = vec![T::ZERO; fuzzyq_core::backup::scratch_len(grid.n_dims(), d)];
        let mut row = vec![T::ZERO; m];
        g.bench_function(format!("greedy_model_{name}"), |b| {
            b.iter(|| {
                i = (i + 1) % STATES;
                view.q_values_with_model(
                    &model,
                    backup,
                    black_box(&states[i]),
                    &mut scratch,
                    &mut row,
                    &mut q,
                )
                .unwrap();
                black_box(q::argmax(&q))
            })
        });
    }
}

fn view_decisions(c: &mut Criterion) {
    let mut g = c.benchmark_group("view");
    let paper = trained(&TrainConfig::default());
    assert!(matches!(paper.values, Values::F32(_)));
    bench_view::<f32>(&mut g, "paper_f32", &paper, true);
    for env in [EnvKind::Dcmotor, EnvKind::Pendulum] {
        let toml = TrainConfig::default_toml(env, Some("toolbox-demo")).unwrap();
        let artifact = trained(&TrainConfig::from_toml(&toml).unwrap());
        bench_view::<f64>(&mut g, &format!("{env}_f64"), &artifact, false);
    }
    g.finish();
}

criterion_group!(benches, decisions, view_decisions);
criterion_main!(benches);
