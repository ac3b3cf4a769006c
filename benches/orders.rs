//! The block path's two orders of the cores: a run's values and greedy actions come back
//! from the internal order the stages run in (each first-block core's slab contiguous) to
//! the grid's row-major order at its end (`to_grid_order`, a transpose: every backend's
//! result, the CPU's and the GPU's), and a resumed run's or a slab shard's values go the
//! other way (`to_internal_order`). On the paper's point masses (2,025 x 2,025) and the
//! paper's Khepera robots (6,137 x 6,137).
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fuzzyq_benches::{BACKUP, default_problems, values};
use fuzzyq_core::solver::{BackupPath, Operator};

fn bench_orders(c: &mut Criterion) {
    let mut g = c.benchmark_group("reorder");
    g.sample_size(10);
    for (name, model, grid) in default_problems() {
        let op = Operator::new(&model, grid.view(), BACKUP, BackupPath::Block).unwrap();
        let v = values::<f32>(grid.n_cores(), 30.0);
        g.throughput(Throughput::Bytes(4 * v.len() as u64));
        g.bench_function(format!("{name}_to_grid"), |b| {
            b.iter(|| black_box(op.to_grid_order(black_box(&v)).unwrap()));
        });
        g.bench_function(format!("{name}_to_internal"), |b| {
            b.iter(|| black_box(op.to_internal_order(black_box(&v)).unwrap()));
        });
    }
    g.finish();
}

criterion_group!(benches, bench_orders);
criterion_main!(benches);
