//! End-to-end fuzzy Q-iteration on the toolbox's fine grids of the classic benchmarks (model
//! tables and every sweep to the preset's `xi`), with both operators: the figures the README
//! compares with the ApproxRL toolbox (DC motor 218 s, pendulum 150 s of table building alone).
#![allow(missing_docs)]

use std::hint::black_box;
use std::ops::ControlFlow;

use criterion::{Criterion, criterion_group, criterion_main};
use fuzzyq_core::solver::{solve, solve_q};
use fuzzyq_sim::model::classic::{
    DcMotor, DcMotorConfig, Pendulum, PendulumConfig, dcmotor, pendulum,
};

fn fine_presets(c: &mut Criterion) {
    let mut g = c.benchmark_group("classic_end_to_end");
    g.sample_size(10);
    let p = dcmotor::preset("fine").unwrap();
    let m = DcMotor::for_preset(DcMotorConfig::default(), &p).unwrap();
    g.bench_function("dcmotor_fine_73x193x9_values", |b| {
        b.iter(|| {
            let grid = p.grid::<f64>().unwrap();
            black_box(solve(&m, &grid, &p.solver_config(), |_| ControlFlow::Continue(())).unwrap())
        })
    });
    g.bench_function("dcmotor_fine_73x193x9_q_values", |b| {
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
    let p = pendulum::preset("fine").unwrap();
    let m = Pendulum::for_preset(PendulumConfig::default(), &p).unwrap();
    g.bench_function("pendulum_fine_73x91x15_values", |b| {
        b.iter(|| {
            let grid = p.grid::<f64>().unwrap();
            black_box(solve(&m, &grid, &p.solver_config(), |_| ControlFlow::Continue(())).unwrap())
        })
    });
    g.bench_function("pendulum_fine_73x91x15_q_values", |b| {
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
    g.finish();
}

criterion_group!(benches, fine_presets);
criterion_main!(benches);
