//! End-to-end fuzzy Q-iteration on the toolbox's fine grids of the classic benchmarks (model
//! tables and every sweep to the preset's `xi`), with both operators: the figures the README
//! compares with the ApproxRL toolbox (DC motor 218 s, pendulum 150 s of table building alone).
#![allow(missing_docs)]

use std::hint::black_box;
use std::ops::ControlFlow;

use criterion::{BenchmarkGroup, Criterion, criterion_group, criterion_main};
use fuzzyq_core::solver::{solve, solve_q};
use fuzzyq_sim::model::classic::{Benchmark, Classic, DcMotor, Pendulum, preset};

/// Both operators on benchmark `S`'s fine preset.
fn both_operators<S: Benchmark>(
    g: &mut BenchmarkGroup<'_, criterion::measurement::WallTime>,
    name: &str,
) {
    let p = preset::<S>("fine").unwrap();
    let m = Classic::<S>::for_preset(S::Config::default(), &p).unwrap();
    g.bench_function(format!("{name}_values"), |b| {
        b.iter(|| {
            let grid = p.grid::<f64>().unwrap();
            black_box(solve(&m, &grid, &p.solver_config(), |_| ControlFlow::Continue(())).unwrap())
        })
    });
    g.bench_function(format!("{name}_q_values"), |b| {
        b.iter(|| {
            let grid = p.grid::<f64>().unwrap();
            black_box(
                solve_q(&m, &grid, &p.solver_config(), |_, _| {
                    ControlFlow::Continue(())
                })
                .unwrap(),
            )
        })
    });
}

fn fine_presets(c: &mut Criterion) {
    let mut g = c.benchmark_group("classic_end_to_end");
    g.sample_size(10);
    both_operators::<DcMotor>(&mut g, "dcmotor_fine_73x193x9");
    both_operators::<Pendulum>(&mut g, "pendulum_fine_73x91x15");
    g.finish();
}

criterion_group!(benches, fine_presets);
criterion_main!(benches);
