//! A run's set-up on the block path (`Operator::new`): the block tables (each block core
//! stepped under each block action, its successor's memberships) and every core's reward. On
//! the paper's point masses (4,100,625 cores, a reward of every state variable) and the
//! paper's Khepera robots (37.7M cores, a reward of the positions alone: evaluated once per
//! pair of positions, 130,321 times, and copied across the headings).
#![allow(missing_docs)]

use std::hint::black_box;

use criterion::{Criterion, criterion_group, criterion_main};
use fuzzyq_benches::{BACKUP, default_problems};
use fuzzyq_core::solver::{BackupPath, Operator};

fn bench_setup(c: &mut Criterion) {
    let mut g = c.benchmark_group("setup");
    g.sample_size(10);
    for (name, model, grid) in default_problems() {
        g.bench_function(format!("{name}_operator"), |b| {
            b.iter(|| {
                let op = Operator::new(&model, grid.view(), BACKUP, BackupPath::Block).unwrap();
                black_box(op.reward_bound())
            });
        });
    }
    g.finish();
}

criterion_group!(benches, bench_setup);
criterion_main!(benches);
