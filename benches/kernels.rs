//! Benchmarks of the hot paths: memberships, one sweep, decisions.
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use fuzzyq_benches::{model, paper_grid, realistic_v, reduced_grid, values, x0};
use fuzzyq_core::model::joint_actions;
use fuzzyq_core::solver::{BackupPath, Kernel, Operator};
use fuzzyq_core::{Backup, q};

const BACKUP: Backup<f32> = Backup::discounted(0.96);

fn memberships(c: &mut Criterion) {
    let grid = paper_grid::<f32>();
    let view = grid.view();
    let x = x0::<f32>();
    let v = values::<f32>(grid.n_cores(), 100.0);
    let mut g = c.benchmark_group("membership");
    g.bench_function("active_cores_paper_8d", |b| {
        b.iter(|| black_box(view.active(black_box(&x)).unwrap().len()))
    });
    g.bench_function("interpolate_v_paper_8d", |b| {
        b.iter(|| black_box(view.active(black_box(&x)).unwrap().interpolate(&v)))
    });
    g.finish();
}

fn sweeps(c: &mut Criterion) {
    let m = model();
    let mut g = c.benchmark_group("sweep");
    g.sample_size(10);
    let paper = paper_grid::<f32>();
    let vp = realistic_v(&paper);
    let op = Operator::new(&m, paper.view(), BACKUP, BackupPath::Block).unwrap();
    g.bench_function(format!("block_paper_4100625x625_{}", op.kernel()), |b| {
        b.iter(|| black_box(op.apply(black_box(&vp)).unwrap()))
    });
    drop(op);
    g.sample_size(20);
    let grid = reduced_grid::<f32>();
    let v = realistic_v(&grid);
    for &k in <Kernel as fuzzyq_core::NamedOption>::ALL
        .iter()
        .filter(|k| k.is_available())
    {
        let block = Operator::new(&m, grid.view(), BACKUP, BackupPath::Block)
            .unwrap()
            .with_kernel(k)
            .unwrap();
        g.bench_function(format!("block_reduced_50625x625_{}", k.name()), |b| {
            b.iter(|| black_box(block.apply(black_box(&v)).unwrap()))
        });
    }
    let small = {
        let mut c = fuzzyq_sim::TrainConfig::default();
        c.grid.position_cores = vec![-6.0, 0.0, 6.0];
        c.grid.velocity_cores = vec![-3.0, 0.0];
        c.grid::<f32>().unwrap()
    };
    let vs = values::<f32>(small.n_cores(), 100.0);
    let generic = Operator::new(&m, small.view(), BACKUP, BackupPath::Generic).unwrap();
    let block_small = Operator::new(&m, small.view(), BACKUP, BackupPath::Block).unwrap();
    g.bench_function("generic_small_1296x625", |b| {
        b.iter(|| black_box(generic.apply(black_box(&vs)).unwrap()))
    });
    g.bench_function("block_small_1296x625", |b| {
        b.iter(|| black_box(block_small.apply(black_box(&vs)).unwrap()))
    });
    g.finish();
}

fn decisions(c: &mut Criterion) {
    let m = model();
    let grid = paper_grid::<f32>();
    let view = grid.view();
    let v = realistic_v(&grid);
    let x = x0::<f32>();
    let op = Operator::new(&m, view, BACKUP, BackupPath::Block).unwrap();
    let joint = joint_actions(&m).unwrap();
    let greedy: Vec<u32> = values::<f64>(grid.n_cores(), 625.0)
        .into_iter()
        .map(|u| u as u32)
        .collect();
    let mut qx = vec![0.0f32; 625];
    let mut u = vec![0.0f32; joint.dim()];
    let mut g = c.benchmark_group("decision");
    g.bench_function("greedy_paper_grid", |b| {
        b.iter(|| {
            op.q_values(&v, black_box(&x), &mut qx).unwrap();
            black_box(q::argmax(&qx))
        })
    });
    g.bench_function("interpolated_paper_grid", |b| {
        b.iter(|| {
            q::interpolated_action(&view, &joint, &greedy, black_box(&x), &mut u).unwrap();
            black_box(u[0])
        })
    });
    g.finish();
}

criterion_group!(benches, memberships, sweeps, decisions);
criterion_main!(benches);
