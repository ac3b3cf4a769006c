//! The GPU path (`fuzzyq-gpu`) against the host reference that sums in the same order: bit for
//! bit with the adapter's rounding (lavapipe rounds each product first; NVIDIA fuses), and
//! against the CPU solver where the adapter fuses. Skipped, with a message, where no adapter
//! exists; `FUZZYQ_REQUIRE_GPU=1` (set by CI, which installs lavapipe) makes that a failure.

use std::ops::ControlFlow;
use std::sync::OnceLock;

use fuzzyq_core::Model;
use fuzzyq_core::solver::{
    self, Buf, Device, Grid, Operator, Precision, Scheme, Solution, SolverConfig, Sweeps,
};
use fuzzyq_gpu::reference::{HostSweeps, Rounding};
use fuzzyq_gpu::{Checks, Evaluation, Gpu, GpuError, GpuSweeps, LastStage};
use fuzzyq_sim::io::config::{EnvConfig, TrainConfig};
use fuzzyq_sim::model::EnvKind;

use crate::solver::values;

/// The adapter, once per test binary; `None` (and a message) where there is none.
fn gpu() -> Option<&'static Gpu> {
    static GPU: OnceLock<Option<Gpu>> = OnceLock::new();
    GPU.get_or_init(|| match Gpu::new() {
        Ok(g) => {
            eprintln!("GPU tests on {:?}", g.summary());
            Some(g)
        }
        Err(e) => {
            assert!(
                std::env::var_os("FUZZYQ_REQUIRE_GPU").is_none(),
                "FUZZYQ_REQUIRE_GPU is set but no adapter opened: {e}"
            );
            eprintln!("skipped: GPU tests need an adapter ({e})");
            None
        }
    })
    .as_ref()
}

fn rounding(g: &Gpu) -> Rounding {
    if g.summary().fused_fma {
        Rounding::Fused
    } else {
        Rounding::Product
    }
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Values, greedy actions and every sweep record's statistics of two runs agree bit for bit.
fn assert_same(a: &Solution<f32>, b: &Solution<f32>, what: &str) {
    assert_eq!(bits(&a.v), bits(&b.v), "{what}: V");
    assert_eq!(a.greedy, b.greedy, "{what}: greedy actions");
    assert_eq!(a.sweeps.len(), b.sweeps.len(), "{what}: sweeps");
    for (x, y) in a.sweeps.iter().zip(&b.sweeps) {
        assert_eq!(x.delta, y.delta, "{what}: sweep {}", x.sweep);
        assert_eq!(
            x.delta_v.to_bits(),
            y.delta_v.to_bits(),
            "{what}: sweep {}",
            x.sweep
        );
    }
    assert_eq!(
        a.final_delta.to_bits(),
        b.final_delta.to_bits(),
        "{what}: final delta"
    );
}

fn noop(_: &solver::Progress, _: Option<&solver::SolverState<'_, f32>>) -> ControlFlow<()> {
    ControlFlow::Continue(())
}

/// The run on the GPU and on the host reference with the adapter's rounding.
fn gpu_and_reference<M: Model<f32> + Sync>(
    g: &Gpu,
    model: &M,
    grid: &Grid<f32>,
    config: &SolverConfig,
) -> (Solution<f32>, Solution<f32>) {
    let on_gpu = fuzzyq_gpu::solve_from(g, model, grid, config, None, false, noop).expect("gpu");
    let r = rounding(g);
    let reference = solver::solve_with(
        model,
        grid,
        config,
        None,
        false,
        &mut |op, _| HostSweeps::new(op, r),
        noop,
    )
    .expect("reference");
    (on_gpu, reference)
}

fn config_of(env: EnvKind) -> TrainConfig {
    TrainConfig::default_for(env).expect("default")
}

/// The point masses on 3 positions x 3 velocities per axis (6,561 cores).
fn pointmass_small() -> TrainConfig {
    let mut c = config_of(EnvKind::Pointmass);
    c.grid.position_cores = vec![-6.0, 0.0, 6.0];
    c.grid.velocity_cores = vec![-3.0, 0.0, 3.0];
    c
}

/// [`pointmass_small`] with an absorbing goal.
fn pointmass_goal() -> TrainConfig {
    let mut c = pointmass_small();
    c.solver.absorbing_goal = true;
    c
}

/// Two robots on 5 positions and 4 headings.
fn khepera_small() -> TrainConfig {
    let mut c = config_of(EnvKind::Khepera);
    c.grid.position_cores = vec![-6.0, -1.0, 0.0, 1.0, 6.0];
    c.grid.heading_divisions = Some(4);
    c
}

/// The run of `c` on the GPU, checked against the reference (and the CPU where the adapter
/// fuses); `None` without a GPU.
fn run_config(c: &TrainConfig) -> Option<Solution<f32>> {
    let g = gpu()?;
    c.validate().expect("valid");
    let model = c.build_model().expect("model");
    let grid = c.grid::<f32>().expect("grid");
    let config = c.solver.solver_config();
    let (on_gpu, reference) = gpu_and_reference(g, &model, &grid, &config);
    assert_eq!(on_gpu.kernel, "wgpu");
    assert_same(&on_gpu, &reference, "gpu against the reference");
    if g.summary().fused_fma {
        let cpu = solver::solve(&model, &grid, &config, |_| ControlFlow::Continue(())).unwrap();
        assert_same(&on_gpu, &cpu, "gpu against the CPU solver");
    }
    Some(on_gpu)
}

#[test]
fn point_masses_match_the_reference_bit_for_bit() {
    run_config(&pointmass_small());
}

#[test]
fn point_masses_by_value_iteration_match_the_reference() {
    // Plain synchronous sweeps: the exact stopping rule's extra passes run too.
    let mut c = pointmass_small();
    c.solver.extrapolate = false;
    c.solver.evaluation_sweeps = 0;
    c.solver.max_sweeps = 30;
    run_config(&c);
}

#[test]
fn khepera_matches_the_reference_bit_for_bit() {
    // The robots' run takes a coarse start, solved on the GPU beside the run's preparation.
    if let Some(s) = run_config(&khepera_small()) {
        assert!(s.coarse.is_some_and(|c| c.sweeps > 0), "{:?}", s.coarse);
    }
}

#[test]
fn dcmotor_matches_the_reference_bit_for_bit() {
    let mut c = config_of(EnvKind::Dcmotor);
    c.solver.max_sweeps = 60;
    run_config(&c);
}

#[test]
fn absorbing_goals_match_the_reference() {
    let mut c = pointmass_goal();
    c.solver.max_sweeps = 20;
    run_config(&c);
}

/// The host reference with fused products is the CPU solver, bit for bit: the reference
/// sums as the CPU kernels do (no GPU needed).
#[test]
fn the_fused_reference_is_the_cpu_solver() {
    for c in [pointmass_small(), config_of(EnvKind::Dcmotor)] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let mut config = c.solver.solver_config();
        config.max_sweeps = config.max_sweeps.min(40);
        let reference = solver::solve_with(
            &model,
            &grid,
            &config,
            None,
            false,
            &mut |op, _| HostSweeps::new(op, Rounding::Fused),
            noop,
        )
        .unwrap();
        let cpu = solver::solve(&model, &grid, &config, |_| ControlFlow::Continue(())).unwrap();
        assert_same(&reference, &cpu, "fused reference against the CPU");
    }
}

/// Every pass of the backend on random values against the reference, one at a time.
fn passes_match<M: Model<f32> + Sync>(g: &Gpu, op: &Operator<'_, f32, M>) {
    let mut gs = GpuSweeps::new(g, op).expect("gpu sweeps");
    let mut hs = HostSweeps::new(op, rounding(g)).expect("reference");
    let n = op.n_cores();
    let (a, b): (Vec<f32>, Vec<f32>) = (values(n, 7, -3.0, 5.0), values(n, 11, -2.0, 2.0));
    let policy: Vec<u32> = values::<f64>(n, 13, 0.0, op.joint().n_joint() as f64)
        .into_iter()
        .map(|x| x as u32)
        .collect();
    gs.load(Buf(0), &a).unwrap();
    gs.load(Buf(1), &b).unwrap();
    hs.load(Buf(0), &a).unwrap();
    hs.load(Buf(1), &b).unwrap();
    let same = |gs: &GpuSweeps, hs: &HostSweeps, what: &str| {
        for k in 0..3 {
            assert_eq!(
                bits(&gs.values(Buf(k)).unwrap()),
                bits(&hs.values(Buf(k)).unwrap()),
                "{what}: buffer {k}"
            );
        }
        assert_eq!(
            gs.policy().unwrap().into_owned(),
            hs.policy().unwrap().into_owned(),
            "{what}: policy"
        );
    };
    gs.backup(Buf(0), Buf(2)).unwrap();
    hs.backup(Buf(0), Buf(2)).unwrap();
    same(&gs, &hs, "backup");
    gs.backup_greedy(Buf(1), Buf(2)).unwrap();
    hs.backup_greedy(Buf(1), Buf(2)).unwrap();
    same(&gs, &hs, "greedy backup");
    gs.greedy(Buf(0)).unwrap();
    hs.greedy(Buf(0)).unwrap();
    same(&gs, &hs, "greedy");
    for s in [0.0f32, 0.37, -1.25] {
        assert_eq!(
            gs.diff_stats(Buf(2), Buf(0), s).unwrap(),
            hs.diff_stats(Buf(2), Buf(0), s).unwrap(),
            "diff stats, shift {s}"
        );
    }
    assert_eq!(
        gs.exact_delta(Buf(0), Buf(1)).unwrap().to_bits(),
        hs.exact_delta(Buf(0), Buf(1)).unwrap().to_bits(),
        "exact delta"
    );
    gs.shift(Buf(2), 0.625).unwrap();
    hs.shift(Buf(2), 0.625).unwrap();
    same(&gs, &hs, "shift");
    let plan = op.block_plan().unwrap();
    if plan.can_evaluate {
        gs.load_policy(&policy).unwrap();
        hs.load_policy(&policy).unwrap();
        gs.evaluate(Buf(0), Buf(2)).unwrap();
        hs.evaluate(Buf(0), Buf(2)).unwrap();
        same(&gs, &hs, "evaluation");
    }
    if plan.rewards.is_some() {
        gs.rewards(Buf(1)).unwrap();
        hs.rewards(Buf(1)).unwrap();
        same(&gs, &hs, "rewards");
    }
    // Every buffer is allocated now (the exact delta's too).
    let bytes = gs.device_bytes();
    drop(gs);
    estimate_is_exact(g, op, Scheme::Value, bytes);
}

/// The memory estimated before allocating a run of `scheme` is `bytes`, what its buffers take,
/// to the byte: a limit of exactly that opens the run, one byte less refuses it (the error,
/// returned, giving the same need).
fn estimate_is_exact<M: Model<f32> + Sync>(
    g: &Gpu,
    op: &Operator<'_, f32, M>,
    scheme: Scheme,
    bytes: u64,
) -> GpuError {
    GpuSweeps::for_scheme(&g.clone().with_memory_limit(bytes), op, scheme).expect("fits");
    let e = GpuSweeps::for_scheme(&g.clone().with_memory_limit(bytes - 1), op, scheme).unwrap_err();
    assert!(
        matches!(e, GpuError::OutOfMemory { need, .. } if need == bytes),
        "{e}"
    );
    e
}

/// The operator a run of `config` prepares.
fn operator<'a, M: Model<f32> + Sync>(
    model: &'a M,
    grid: &'a Grid<f32>,
    config: &SolverConfig,
) -> Operator<'a, f32, M> {
    let backup = fuzzyq_core::backup::Backup {
        gamma: config.gamma as f32,
        absorbing_goal: config.absorbing_goal,
    };
    Operator::new(model, grid.view(), backup, config.path).unwrap()
}

fn operator_passes(c: &TrainConfig) {
    let Some(g) = gpu() else { return };
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let op = operator(&model, &grid, &config);
    passes_match(g, &op);
}

#[test]
fn every_pass_matches_the_reference_on_point_masses() {
    operator_passes(&pointmass_small());
    // The fused last stage takes a core's 343 product columns in chunks per lane.
    operator_passes(&seven_forces());
    operator_passes(&pointmass_goal());
}

#[test]
fn every_pass_matches_the_reference_on_khepera_and_dcmotor() {
    operator_passes(&khepera_small());
    operator_passes(&config_of(EnvKind::Dcmotor));
}

/// Three point masses (six blocks) on 2 positions x 2 velocities per axis (4,096 cores) and
/// forces -2, 0 and 2 N (729 joint actions); `shaped`: the reward of the action (full rows
/// and a reward table).
fn three_point_masses(shaped: bool) -> TrainConfig {
    let mut c = config_of(EnvKind::Pointmass);
    c.grid.position_cores = vec![-6.0, 6.0];
    c.grid.velocity_cores = vec![-3.0, 3.0];
    let EnvConfig::Pointmass(p) = &mut c.env else {
        unreachable!("a point-mass config")
    };
    p.agents = 3;
    p.force_levels = vec![-2.0, 0.0, 2.0];
    if shaped {
        p.reward = fuzzyq_sim::model::pointmass::RewardShape::Shaped;
    }
    c
}

/// Policy evaluation of random values under a random policy on the GPU `g` (its split, and
/// the values' bits) and on the reference (the values' bits).
fn evaluation_bits<M: Model<f32> + Sync>(
    g: &Gpu,
    op: &Operator<'_, f32, M>,
) -> ((usize, Vec<u32>), Vec<u32>) {
    let n = op.n_cores();
    let v = values(n, 7, -3.0, 5.0);
    let policy: Vec<u32> = values::<f64>(n, 13, 0.0, op.joint().n_joint() as f64)
        .into_iter()
        .map(|x| x as u32)
        .collect();
    let mut hs = HostSweeps::new(op, rounding(g)).unwrap();
    hs.load(Buf(0), &v).unwrap();
    hs.load_policy(&policy).unwrap();
    hs.evaluate(Buf(0), Buf(1)).unwrap();
    let mut gs = GpuSweeps::new(g, op).unwrap();
    gs.load(Buf(0), &v).unwrap();
    gs.load_policy(&policy).unwrap();
    gs.evaluate(Buf(0), Buf(1)).unwrap();
    let got = bits(&gs.values(Buf(1)).unwrap());
    (
        (gs.evaluation_stages(), got),
        bits(&hs.values(Buf(1)).unwrap()),
    )
}

#[test]
fn policy_evaluation_through_every_split_gives_the_same_bits() {
    let Some(g) = gpu() else { return };
    // An evaluation sweep runs the first `k` stages of a full backup for every action, then a
    // thread per core nests its own action's rows of the other blocks over the last of them
    // (`k = 0`: every block over `V`). Every `k`, with batches of whole slabs and the
    // smallest (below fixed blocks), and `V` in parts, against the reference, bit for bit.
    for (c, expected) in [
        (pointmass_small(), [2, 1]),
        (three_point_masses(false), [3, 2]),
        (khepera_small(), [1, 0]),
    ] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let config = c.solver.solver_config();
        let op = operator(&model, &grid, &config);
        let plan = op.block_plan().unwrap();
        assert!(plan.can_evaluate);
        let (n, nb) = (op.n_cores(), plan.tables.len());
        for k in 0..nb {
            let split = g.clone().with_evaluation(Evaluation::Stages(k as u32));
            for (gk, what) in [
                (split.clone(), "default batches"),
                (split.clone().with_batch_bytes(1), "the smallest batches"),
                (split.with_part_bytes(1), "V in parts"),
            ] {
                let ((stages, got), want) = evaluation_bits(&gk, &op);
                assert_eq!(stages, k);
                assert!(got == want, "{n} cores, {k} stages, {what}");
            }
        }
        // The default: the split with the least estimated work, which depends on whether
        // the stages' rows are compiled in (the default on lavapipe) or read from the tables
        // (on a GPU).
        let auto = [true, false].map(|compiled_in| {
            let g = g.clone().with_unrolled_stages(compiled_in);
            GpuSweeps::new(&g, &op).unwrap().evaluation_stages()
        });
        eprintln!("{n} cores in {nb} blocks: evaluation runs {auto:?} stage(s) first");
        assert_eq!(auto, expected, "{n} cores: stages compiled in, read");
    }
    // A stage output cut into parts (three point masses under a binding of 4 KB: the first
    // four, `stage_outputs_over_a_binding_in_parts_give_the_same_bits`) is never read per
    // core: a split asked for that would read one takes the largest below it that reads
    // one buffer (or `V`), with the same bits.
    let c = three_point_masses(false);
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let op = operator(&model, &grid, &c.solver.solver_config());
    let cut = g.clone().with_binding_limit(4 << 10);
    for (k, taken) in [(2, 0), (4, 0), (5, 5), (9, 5)] {
        let split = cut.clone().with_evaluation(Evaluation::Stages(k));
        let ((stages, got), want) = evaluation_bits(&split, &op);
        assert_eq!(stages, taken, "stages:{k}");
        assert!(got == want, "stages:{k}");
    }
    assert_eq!(Evaluation::parse("nested"), Some(Evaluation::Stages(0)));
    assert_eq!(Evaluation::parse("stages:2"), Some(Evaluation::Stages(2)));
    assert_eq!(Evaluation::parse("auto"), Some(Evaluation::Auto));
    assert_eq!(Evaluation::parse("stages"), None);
}

/// The batch levels of `op`'s passes under stage budgets from 1 byte to the default, each
/// budget's passes checked against the reference.
fn batch_levels<M: Model<f32> + Sync>(g: &Gpu, op: &Operator<'_, f32, M>) -> Vec<usize> {
    let mut levels = Vec::new();
    for budget in [1u64, 1 << 10, 1 << 14, 1 << 18, 1 << 22, 1 << 26] {
        let small = g.clone().with_batch_bytes(budget);
        let b = GpuSweeps::new(&small, op).unwrap().batches();
        if !levels.contains(&b.level) {
            eprintln!("budget {budget} B: {b}");
            passes_match(&small, op);
            levels.push(b.level);
        }
    }
    levels
}

#[test]
fn every_batching_gives_the_same_bits() {
    let Some(g) = gpu() else { return };
    // Small budgets cut a pass into batches of one slab, then of cores of later blocks below
    // fixed cores of earlier ones; every pass keeps the reference's bits, as a whole run
    // keeps the default batches'. The levels the budgets reach, from the smallest budget up.
    for (c, expected) in [
        (pointmass_small(), vec![2, 1, 0]),
        (three_point_masses(false), vec![4, 3, 1, 0]),
        (three_point_masses(true), vec![4, 2, 0]),
    ] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let config = c.solver.solver_config();
        let op = operator(&model, &grid, &config);
        assert_eq!(batch_levels(g, &op), expected);
        // Whole runs of a few sweeps (each budget's passes were checked above).
        let config = SolverConfig {
            max_sweeps: 8,
            ..config
        };
        let small = g.clone().with_batch_bytes(1);
        let a = fuzzyq_gpu::solve_from(&small, &model, &grid, &config, None, false, noop).unwrap();
        let b = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap();
        assert_same(&a, &b, "the smallest batches against the default");
    }
}

#[test]
fn v_in_parts_gives_the_same_bits() {
    let Some(g) = gpu() else { return };
    // `V` cut into parts (one slab each at the smallest, as a `V` over one storage binding
    // is): the first stage and policy evaluation read across parts, the other passes run a
    // part at a time, the goal bits and the reward table are cut with them. Every pass keeps
    // the reference's bits, as a whole run keeps one part's.
    for c in [
        pointmass_small(),
        pointmass_goal(),
        khepera_small(),
        three_point_masses(false),
        three_point_masses(true),
    ] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let config = c.solver.solver_config();
        let op = operator(&model, &grid, &config);
        let v_bytes = 4 * op.n_cores() as u64;
        let mut counts = Vec::new();
        for bytes in [1, v_bytes / 3, v_bytes / 2] {
            let cut = g.clone().with_part_bytes(bytes);
            let parts = GpuSweeps::new(&cut, &op).unwrap().parts();
            if counts.contains(&parts) {
                continue;
            }
            counts.push(parts);
            eprintln!("{} cores in {parts} parts", op.n_cores());
            passes_match(&cut, &op);
        }
        assert!(counts.iter().all(|&p| p > 1), "{counts:?}");
        assert_eq!(GpuSweeps::new(g, &op).unwrap().parts(), 1);
        // Whole runs of a few sweeps (every pass was checked above): what they add is the
        // driver's buffers and the result read back across parts.
        let config = SolverConfig {
            max_sweeps: 8,
            ..config
        };
        let b = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap();
        // The result read back a slab at a time: from parts of one slab, and from parts of
        // several (pieces within a part).
        for cut in [
            g.clone().with_part_bytes(1),
            g.clone().with_part_bytes(v_bytes / 2).with_read_bytes(1),
        ] {
            let a =
                fuzzyq_gpu::solve_from(&cut, &model, &grid, &config, None, false, noop).unwrap();
            assert_same(&a, &b, "V in parts against one part");
        }
    }
}

#[test]
fn the_last_stage_from_workgroup_memory_gives_the_same_bits() {
    let Some(g) = gpu() else { return };
    // `LastStage::Tile`: a workgroup per item of the stage before, whose values it loads once
    // into workgroup memory (the last block's cores times the product actions before it:
    // 4.5 KB for these point masses), its cores' lanes reading them there. Every pass of
    // every mode keeps the reference's bits, with batches of whole slabs or of cores below
    // fixed blocks, and a whole run the default kernels' bits.
    let tile = |threads| g.clone().with_last_stage(LastStage::Tile { threads });
    let runs = [
        (pointmass_small(), vec![32, 256]),
        (three_point_masses(false), vec![64]),
        (pointmass_goal(), vec![128]),
        (khepera_small(), vec![128]),
    ];
    for (c, threads) in runs {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let config = c.solver.solver_config();
        let op = operator(&model, &grid, &config);
        for t in threads {
            let gs = GpuSweeps::new(&tile(t), &op).unwrap();
            let name = gs.last_stage();
            eprintln!(
                "{} cores, {t} threads: {name:?}, {}",
                op.n_cores(),
                gs.batches()
            );
            if matches!(c.env, EnvConfig::Pointmass(_)) {
                assert_eq!(name, Some("lastw"), "the item's values fit");
                assert!(!gs.uses_subgroups());
            }
            drop(gs);
            passes_match(&tile(t), &op);
            passes_match(&tile(t).with_batch_bytes(1), &op);
        }
    }
    let c = pointmass_small();
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let a = fuzzyq_gpu::solve_from(&tile(128), &model, &grid, &config, None, false, noop).unwrap();
    let b = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap();
    assert_same(
        &a,
        &b,
        "the last stage from workgroup memory against the default",
    );
    assert_eq!(
        LastStage::parse("tile"),
        Some(LastStage::Tile { threads: 128 })
    );
    assert_eq!(
        LastStage::parse("tile:64"),
        Some(LastStage::Tile { threads: 64 })
    );
    assert_eq!(LastStage::parse("tile:100"), None);
}

#[test]
fn the_last_stage_staged_in_workgroup_memory_gives_the_same_bits() {
    let Some(g) = gpu() else { return };
    // `LastStage::Staged`: a workgroup per item of the stage before, which computes that
    // item's values into workgroup memory from the stage before that (so the stage before
    // the last is not dispatched), then its cores a few lanes each. Every pass of every mode
    // keeps the reference's bits with workgroups of 8 to 1024 threads (one lane per core
    // and several rounds of cores, or several lanes per core), the item's columns in one
    // pass or several (down to one column a pass, the last pass short), with batches of
    // whole slabs and the smallest (items cut at a batch's ends, the stage before that held
    // across batches); models of two blocks (Khepera) take the fallback; a whole run keeps the
    // default kernels' bits.
    let staged = |threads, columns| {
        g.clone()
            .with_last_stage(LastStage::Staged { threads, columns })
    };
    let fallback = if g.summary().software {
        "lastm"
    } else {
        "last1"
    };
    for (c, threads) in [
        (
            pointmass_small(),
            // 8 threads (below what the setting takes): one lane per core, cores in two
            // rounds.
            vec![
                (32, None),
                (256, None),
                (1024, None),
                (64, Some(7)),
                (32, Some(1)),
                (8, Some(5)),
            ],
        ),
        (pointmass_goal(), vec![(64, None)]),
        (
            three_point_masses(false),
            vec![(128, None), (512, Some(100))],
        ),
        (seven_forces(), vec![(256, None), (128, Some(50))]),
        (khepera_small(), vec![(256, None)]),
    ] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let config = c.solver.solver_config();
        let op = operator(&model, &grid, &config);
        let blocks = op.block_plan().unwrap().tables.len();
        for (i, (t, columns)) in threads.into_iter().enumerate() {
            let gs = GpuSweeps::new(&staged(t, columns), &op).unwrap();
            let name = gs.last_stage();
            eprintln!(
                "{} cores, {blocks} blocks, {t} threads, columns {columns:?}: {name:?}, {}",
                op.n_cores(),
                gs.batches()
            );
            let want = if blocks >= 3 { "lasts" } else { fallback };
            assert_eq!(name, Some(want));
            drop(gs);
            passes_match(&staged(t, columns), &op);
            // Batches cut items apart whatever a workgroup does within them: the smallest
            // with each problem's first workgroup.
            if i == 0 {
                passes_match(&staged(t, columns).with_batch_bytes(1), &op);
            }
        }
    }
    let c = three_point_masses(false);
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let run = |g: &Gpu| fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop);
    let b = run(g).unwrap();
    for columns in [None, Some(10)] {
        let a = run(&staged(256, columns)).unwrap();
        assert_same(&a, &b, "the last stage staged against the default");
    }
    let parsed = |threads, columns| Some(LastStage::Staged { threads, columns });
    assert_eq!(LastStage::parse("staged"), parsed(256, None));
    assert_eq!(LastStage::parse("staged:1024"), parsed(1024, None));
    assert_eq!(LastStage::parse("staged:64:7"), parsed(64, Some(7)));
    for bad in [
        "staged:16",
        "staged:300",
        "staged:2048",
        "staged:",
        "staged:64:0",
        "staged:64:",
        "staged:64:x",
        "staged:100:7",
    ] {
        assert_eq!(LastStage::parse(bad), None, "{bad}");
    }
}

/// How lanes may exchange values on `g`: by subgroup operations where it has them, and
/// always through workgroup memory.
fn exchanges(g: &Gpu) -> Vec<bool> {
    if g.summary().subgroup_size.is_some() {
        vec![true, false]
    } else {
        vec![false]
    }
}

/// A last stage with the rows compiled in (`last`) against the reference: every pass of
/// every mode on the models below, lanes exchanging by subgroups and through workgroup
/// memory, with batches of whole slabs and the smallest (cores below fixed blocks, items cut
/// at a batch's ends); its kernel on each model is `want(blocks)`. Then a whole run of
/// `whole` against the default kernels' bits. Three point masses have 243 product actions
/// before the last block and seven forces 343: several chunks of columns per lane, the last
/// one past the end.
fn compiled_last_stage_matches(
    g: &Gpu,
    last: LastStage,
    want: fn(usize) -> &'static str,
    whole: TrainConfig,
) {
    let gpu = |subgroups| g.clone().with_last_stage(last).with_subgroups(subgroups);
    for c in [
        pointmass_small(),
        pointmass_goal(),
        khepera_small(),
        three_point_masses(false),
        seven_forces(),
    ] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let config = c.solver.solver_config();
        let op = operator(&model, &grid, &config);
        let blocks = op.block_plan().unwrap().tables.len();
        for subgroups in exchanges(g) {
            let gs = GpuSweeps::new(&gpu(subgroups), &op).unwrap();
            eprintln!(
                "{} cores, {blocks} blocks, subgroups {subgroups}: {:?}, {}",
                op.n_cores(),
                gs.last_stage(),
                gs.batches()
            );
            assert_eq!(gs.last_stage(), Some(want(blocks)));
            assert_eq!(
                gs.uses_subgroups(),
                subgroups && g.summary().subgroup_size.is_some()
            );
            drop(gs);
            for budget in [u64::MAX, 1] {
                passes_match(&gpu(subgroups).with_batch_bytes(budget), &op);
            }
        }
    }
    let model = whole.build_model().unwrap();
    let grid = whole.grid::<f32>().unwrap();
    let config = whole.solver.solver_config();
    let a = fuzzyq_gpu::solve_from(&gpu(true), &model, &grid, &config, None, false, noop).unwrap();
    let b = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap();
    assert_same(&a, &b, "the rows compiled in against the default");
}

#[test]
fn the_last_stage_with_its_rows_compiled_in_gives_the_same_bits() {
    let Some(g) = gpu() else { return };
    // `LastStage::Unrolled`: the last block's rows compiled into the kernel as constants, a
    // workgroup per item of the stage before, the cores' maxima reduced over the lanes by
    // halving.
    compiled_last_stage_matches(g, LastStage::Unrolled, |_| "lastu", pointmass_small());
    assert_eq!(LastStage::parse("unrolled"), Some(LastStage::Unrolled));
}

#[test]
fn the_last_stage_joined_with_the_stage_before_gives_the_same_bits() {
    let Some(g) = gpu() else { return };
    // `LastStage::Joined`: the last stage's kernel computes the stage before it (each lane
    // its own columns' values, from the stage before that), which is then not dispatched;
    // with the smallest batches, one item of the stage before each, read from the stage
    // before that, held across batches. Models of two blocks or fewer (Khepera here) take
    // the last stage unrolled.
    let want = |blocks| if blocks >= 3 { "lastj" } else { "lastu" };
    compiled_last_stage_matches(g, LastStage::Joined, want, three_point_masses(false));
    assert_eq!(LastStage::parse("joined"), Some(LastStage::Joined));
}

#[test]
fn the_stages_with_their_rows_compiled_in_give_the_same_bits() {
    let Some(g) = gpu() else { return };
    // `Gpu::with_unrolled_stages`: every stage a full backup runs as a stage compiled with its
    // block's rows as constants, a thread per element of an item of the stage before taking
    // every core below it. Every pass of every mode keeps the reference's bits: with `V` read
    // through its parts by the first stage, with batches of whole slabs, of cores below fixed
    // blocks (items cut at a batch's ends) and of stage outputs in parts, and where the last
    // stage writes full rows (the shaped reward of three point masses, dcmotor's renumbered
    // actions, one block of 14,089 cores, too many rows to compile in: the kernel it had);
    // a whole run keeps the default kernels' bits.
    let unrolled = g.clone().with_unrolled_stages(true);
    for (c, want) in [
        (pointmass_small(), "stage_u"),
        (khepera_small(), "stage_u"),
        (three_point_masses(false), "stage_u"),
        (three_point_masses(true), "stage_u"),
        (config_of(EnvKind::Dcmotor), "stage_c"),
    ] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let config = c.solver.solver_config();
        let op = operator(&model, &grid, &config);
        let gs = GpuSweeps::new(&unrolled, &op).unwrap();
        let kernels = gs.stage_kernels();
        eprintln!("{} cores: {kernels:?}, {}", op.n_cores(), gs.batches());
        assert!(!kernels.is_empty() && kernels.iter().all(|k| *k == want));
        drop(gs);
        if want != "stage_u" {
            // The kernel it had, whose passes the other tests check.
            continue;
        }
        passes_match(&unrolled, &op);
        for budget in [1, 1 << 10] {
            passes_match(&unrolled.clone().with_batch_bytes(budget), &op);
        }
    }
    let c = three_point_masses(false);
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let op = operator(&model, &grid, &config);
    let cut = unrolled
        .clone()
        .with_binding_limit(4 << 10)
        .with_part_bytes(1);
    assert_eq!(
        GpuSweeps::new(&cut, &op).unwrap().stage_parts(),
        [4, 4, 2, 2, 1]
    );
    passes_match(&cut, &op);
    let a = fuzzyq_gpu::solve_from(&unrolled, &model, &grid, &config, None, false, noop).unwrap();
    let b = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap();
    assert_same(&a, &b, "the stages' rows compiled in against the default");
}

#[test]
fn stage_outputs_over_a_binding_in_parts_give_the_same_bits() {
    let Some(g) = gpu() else { return };
    // Three point masses on the paper's cores have one slab's first stage at 3.69 GB, over
    // wgpu's 2 GiB binding (refused on an H200 before stage outputs came in parts). Here
    // blocks of 4 cores and 3 actions: one slab of `V` 4 KB, the first stage's one item
    // 12 KB, the second's 9 KB; under a binding of 8 KB both are cut into parts of whole
    // columns' values, under 4 KB the first four. Every pass keeps the reference's bits and
    // a whole run the uncut run's.
    let c = three_point_masses(false);
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let op = operator(&model, &grid, &config);
    assert_eq!(GpuSweeps::new(g, &op).unwrap().stage_parts(), [1; 5]);
    let b = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap();
    for (kb, want) in [(8, [2, 2, 1, 1, 1]), (4, [4, 4, 2, 2, 1])] {
        let cut = g.clone().with_binding_limit(kb << 10);
        let gs = GpuSweeps::new(&cut, &op).unwrap();
        assert_eq!(gs.stage_parts(), want, "{kb} KB: {}", gs.batches());
        drop(gs);
        passes_match(&cut, &op);
        let a = fuzzyq_gpu::solve_from(&cut, &model, &grid, &config, None, false, noop).unwrap();
        assert_same(&a, &b, "stage outputs in parts against one buffer each");
    }
}

#[test]
fn modified_policy_iteration_holds_v_twice() {
    let Some(g) = gpu() else { return };
    // The buffers modified policy iteration's driver uses: V twice and the policy, checked
    // against the memory to the byte before allocating (three point masses on the paper's
    // cores fit one H200 this way). A buffer beyond them is made when a pass first asks.
    let c = pointmass_small();
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let op = operator(&model, &grid, &config);
    let n = op.n_cores();
    let mpi = Scheme::ModifiedPolicy;
    let mut gs = GpuSweeps::for_scheme(g, &op, mpi).unwrap();
    gs.load(Buf(0), &values(n, 7, -3.0, 5.0)).unwrap();
    gs.backup_greedy(Buf(0), Buf(1)).unwrap();
    gs.evaluate(Buf(1), Buf(0)).unwrap();
    gs.diff_stats(Buf(1), Buf(0), 0.0).unwrap();
    gs.shift(Buf(0), 0.5).unwrap();
    gs.rewards(Buf(1)).unwrap();
    gs.greedy(Buf(0)).unwrap();
    let bytes = gs.device_bytes();
    let e = estimate_is_exact(g, &op, mpi, bytes);
    assert!(e.to_string().contains("V twice and the policy"), "{e}");
    // Value iteration's third V and the exact delta's two work buffers, made on first use.
    assert_eq!(gs.values(Buf(2)).unwrap().into_owned(), vec![0.0; n]);
    gs.backup(Buf(0), Buf(2)).unwrap();
    gs.exact_delta(Buf(2), Buf(0)).unwrap();
    assert_eq!(gs.device_bytes(), bytes + 3 * 4 * n as u64);
}

#[test]
fn lanes_reduced_in_memory_or_by_subgroups_give_the_same_bits() {
    let Some(g) = gpu() else { return };
    for c in [pointmass_small(), khepera_small()] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let config = c.solver.solver_config();
        let memory = g.clone().with_subgroups(false);
        let a = fuzzyq_gpu::solve_from(&memory, &model, &grid, &config, None, false, noop).unwrap();
        let b = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap();
        assert_same(&a, &b, "lanes reduced in memory against subgroups");
        let op = operator(&model, &grid, &config);
        assert!(!GpuSweeps::new(&memory, &op).unwrap().uses_subgroups());
        let sg = GpuSweeps::new(g, &op).unwrap().uses_subgroups();
        assert_eq!(
            sg,
            g.summary().subgroup_size.is_some(),
            "subgroups where the adapter has them"
        );
        // Every pass too, with the lanes reduced in memory.
        passes_match(&memory, &op);
    }
}

#[test]
fn wgpus_runtime_checks_change_no_bit() {
    let Some(g) = gpu() else { return };
    // The kernels compiled with every one of wgpu's runtime checks (workgroup memory zeroed,
    // loops counted, divisions guarded, indices clamped; the other tests run them without,
    // the default): every kind of stage and last stage, every pass, the reference's bits. A
    // check that changed a result would mean a kernel reads memory it never wrote or indexes
    // past an array.
    assert_eq!(Checks::parse("all"), Some(Checks::ALL));
    assert_eq!(Checks::parse("none"), Some(Checks::NONE));
    assert_eq!(
        Checks::parse("zero, bounds"),
        Some(Checks {
            zero_workgroup: true,
            bounds: true,
            ..Checks::NONE
        })
    );
    for bad in ["", "al", "zero,,bounds", "loops;division"] {
        assert_eq!(Checks::parse(bad), None, "{bad:?}");
    }
    for c in ["all", "none", "loops", "zero,division,bounds"] {
        assert_eq!(Checks::parse(c).unwrap().to_string(), c);
    }
    let plain = g.clone().with_unrolled_stages(false);
    let kernels = [
        g.clone()
            .with_unrolled_stages(true)
            .with_last_stage(LastStage::Unrolled),
        g.clone()
            .with_unrolled_stages(true)
            .with_last_stage(LastStage::Joined),
        plain.clone().with_last_stage(LastStage::Rows),
        plain
            .clone()
            .with_merged_stages(false)
            .with_last_stage(LastStage::MERGED),
        plain
            .clone()
            .with_last_stage(LastStage::Tile { threads: 64 }),
        plain.clone().with_last_stage(LastStage::Staged {
            threads: 64,
            columns: Some(5),
        }),
    ];
    for c in [pointmass_small(), khepera_small()] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let op = operator(&model, &grid, &c.solver.solver_config());
        for k in &kernels {
            let checked = k.clone().with_checks(Checks::ALL).unwrap();
            assert_eq!(checked.checks(), Checks::ALL);
            passes_match(&checked, &op);
        }
    }
    // A whole run with the lanes reduced in workgroup memory.
    let c = pointmass_small();
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let memory = g.clone().with_subgroups(false);
    let checked = memory.clone().with_checks(Checks::ALL).unwrap();
    let a = fuzzyq_gpu::solve_from(&checked, &model, &grid, &config, None, false, noop).unwrap();
    let b = fuzzyq_gpu::solve_from(&memory, &model, &grid, &config, None, false, noop).unwrap();
    assert_same(&a, &b, "every runtime check against the default's");
}

/// Two point masses on 2 positions x 2 velocities per axis (256 cores) with seven forces per
/// axis (2,401 joint actions): the last block's 343 product columns per core are more than a
/// lane's chunk of them, as the paper's three masses' 3,125 are (32 lanes per core, 11 columns
/// each: `NCH` = 2 chunks of 8 one row at a time, 3 of 5 where the 7 rows merge).
fn seven_forces() -> TrainConfig {
    let mut c = config_of(EnvKind::Pointmass);
    c.grid.position_cores = vec![-6.0, 6.0];
    c.grid.velocity_cores = vec![-3.0, 3.0];
    let EnvConfig::Pointmass(p) = &mut c.env else {
        unreachable!("a point-mass config")
    };
    p.force_levels = vec![-2.0, -1.0, -0.2, 0.0, 0.2, 1.0, 2.0];
    c
}

#[test]
fn kernels_by_rows_or_merged_give_the_same_bits() {
    let Some(g) = gpu() else { return };
    // The kernels before the merge: every stage and the last one row at a time (the stages'
    // rows not compiled in, as they are by default on a software adapter).
    let plain = g.clone().with_unrolled_stages(false);
    let rows = plain
        .clone()
        .with_merged_stages(false)
        .with_last_stage(LastStage::Rows);
    let merged = |cores| plain.clone().with_last_stage(LastStage::Merged { cores });
    let c = pointmass_small();
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let a = fuzzyq_gpu::solve_from(&rows, &model, &grid, &config, None, false, noop).unwrap();
    let b = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap();
    assert_same(&a, &b, "rows against the adapter's default");
    // The default kernels: the rows compiled in for every problem on a software adapter
    // (lavapipe); on a GPU from `COMPILE_IN_FROM` multiply-adds per full backup, below which
    // (this problem) the stages are merged and the last stage takes one row at a time. The
    // rule itself on any adapter: a threshold at this problem's size and one above it; and a
    // choice made explicitly holds for every size.
    let op = operator(&model, &grid, &config);
    let kernels = |g: &Gpu| {
        let s = GpuSweeps::new(g, &op).unwrap();
        (s.stage_kernels()[0], s.last_stage())
    };
    let (compiled_in, read) = (("stage_u", Some("lastu")), ("stage_m", Some("last1")));
    let size = op.multiply_adds_per_sweep().unwrap();
    assert!(size < fuzzyq_gpu::COMPILE_IN_FROM);
    let want = if g.summary().software {
        compiled_in
    } else {
        read
    };
    assert_eq!(kernels(g), want, "{:?}", g.summary());
    assert_eq!(
        kernels(&g.clone().with_rows_compiled_in_from(size)),
        compiled_in
    );
    let above = g.clone().with_rows_compiled_in_from(size * 1.5);
    assert_eq!(kernels(&above), read);
    let chosen = above
        .with_unrolled_stages(true)
        .with_last_stage(LastStage::Unrolled);
    assert_eq!(kernels(&chosen), compiled_in);
    // Every pass of either kernel, cores in turn or not, lanes reduced by subgroups or in
    // memory (the adapter's default in the tests above).
    let variants = [
        (rows.clone(), "stage_c", "last1"),
        (merged(1).with_merged_stages(false), "stage_c", "lastm"),
        (merged(3), "stage_m", "lastm"),
        (
            plain.clone().with_last_stage(LastStage::Rows),
            "stage_m",
            "last1",
        ),
    ];
    for c in [
        pointmass_small(),
        pointmass_goal(),
        khepera_small(),
        config_of(EnvKind::Dcmotor),
    ] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let op = operator(&model, &grid, &c.solver.solver_config());
        for (gpu, stage, last) in &variants {
            for sg in [true, false] {
                let gpu = gpu.clone().with_subgroups(sg);
                let gs = GpuSweeps::new(&gpu, &op).unwrap();
                // One block: a thread per core, rows one at a time.
                let one_block = matches!(c.env, EnvConfig::Dcmotor(_));
                let want = if one_block { "stage_c" } else { stage };
                assert!(gs.stage_kernels().iter().all(|k| *k == want), "{want}");
                assert_eq!(gs.last_stage(), Some(*last));
                drop(gs);
                passes_match(&gpu, &op);
            }
        }
    }
    // The columns in chunks per lane; and six blocks, the reward of the action (full rows):
    // one row at a time.
    for c in [seven_forces(), three_point_masses(true)] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        passes_match(&rows, &operator(&model, &grid, &c.solver.solver_config()));
    }
}

/// What the merged kernels save on the paper's grid (no adapter needed): every block core's
/// 5 rows hold 18.3 entries between them and merge into 8.1 steps (the figures of
/// `LastStage::Merged` and BENCHMARKS.md).
#[test]
fn the_papers_rows_merge_into_fewer_steps() {
    let c = config_of(EnvKind::Pointmass);
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let op = operator(&model, &grid, &c.solver.solver_config());
    let plan = op.block_plan().unwrap();
    assert_eq!(plan.tables.len(), 4);
    for t in &plan.tables {
        let steps: usize = (0..t.n_cores)
            .map(|core| t.merged_steps(core, |_, _, _, _| {}).unwrap())
            .sum();
        let per_core = |n: usize| format!("{:.1}", n as f64 / t.n_cores as f64);
        assert_eq!((t.n_cores, t.n_actions), (45, 5));
        assert_eq!(per_core(t.col.len()), "18.3");
        assert_eq!(per_core(steps), "8.1");
    }
}

#[test]
fn refusals_are_one_line_errors() {
    let Some(g) = gpu() else { return };
    // Asynchronous sweeps.
    let c = pointmass_small();
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let mut config = c.solver.solver_config();
    config.sweep = solver::SweepMode::Asynchronous;
    let mut errors = Vec::new();
    let e = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap_err();
    assert!(e.to_string().contains("synchronous"), "{e}");
    errors.push(e);
    // The generic path.
    let mut config = c.solver.solver_config();
    config.path = solver::BackupPath::Generic;
    let e = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap_err();
    assert!(matches!(e, GpuError::Unsupported(_)), "{e}");
    assert!(e.to_string().contains("block"), "{e}");
    errors.push(e);
    // A binding limit below V's size: refused before allocating.
    let tiny = g.clone().with_binding_limit(1024);
    let config = c.solver.solver_config();
    let e = fuzzyq_gpu::solve_from(&tiny, &model, &grid, &config, None, false, noop).unwrap_err();
    assert!(matches!(e, GpuError::TooLarge { .. }), "{e}");
    assert!(e.to_string().contains("V needs"), "{e}");
    errors.push(e);
    // Less device memory than the run's buffers take: refused before allocating, in GB.
    if g.summary().backend == "vulkan" {
        assert!(
            g.summary().memory.is_some_and(|m| m > 0),
            "{:?}",
            g.summary()
        );
    }
    let small = g.clone().with_memory_limit(100_000);
    let e = fuzzyq_gpu::solve_from(&small, &model, &grid, &config, None, false, noop).unwrap_err();
    assert!(matches!(e, GpuError::OutOfMemory { .. }), "{e}");
    assert!(e.to_string().contains("GB of GPU memory ("), "{e}");
    errors.push(e);
    for e in errors {
        assert!(!e.to_string().contains('\n'), "one line: {e}");
    }
}

#[test]
fn the_config_refuses_what_the_gpu_does_not_run() {
    let mut c = pointmass_small();
    c.solver.device = Device::Gpu;
    c.solver.precision = Precision::F64;
    let e = c.validate().unwrap_err().to_string();
    assert!(e.starts_with("solver.device: \"gpu\" runs in f32"), "{e}");
    let mut c = pointmass_small();
    c.solver.device = Device::Gpu;
    c.solver.sweep = solver::SweepMode::Asynchronous;
    assert!(c.validate().unwrap_err().to_string().contains("sync"));
    let text = "[solver]\ndevice = \"tpu\"\n";
    let e = TrainConfig::from_toml(text).unwrap_err().to_string();
    assert!(e.contains("device"), "{e}");
}

#[test]
fn training_on_the_gpu_writes_the_reference_policy() {
    let Some(g) = gpu() else { return };
    let mut c = pointmass_small();
    c.solver.device = Device::Gpu;
    let artifact = fuzzyq_sim::train::train(&c, |_| ControlFlow::Continue(())).unwrap();
    assert_eq!(artifact.summary.kernel, "wgpu");
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let r = rounding(g);
    let reference = solver::solve_with(
        &model,
        &grid,
        &config,
        None,
        false,
        &mut |op, _| HostSweeps::new(op, r),
        noop,
    )
    .unwrap();
    let EnvConfig::Pointmass(_) = &c.env else {
        unreachable!()
    };
    assert_eq!(artifact.greedy, reference.greedy);
}

/// A GPU run checkpointed after some sweeps and continued from each checkpoint file ends in
/// the uninterrupted run's policy, bit for bit, in both schemes: modified policy iteration
/// (`V` and the policy read back) and extrapolated value iteration (`V`, the previous `V` and
/// the shift). The checkpoints borrow the state read back, written as they are encoded.
#[test]
fn gpu_runs_continue_from_their_checkpoints_bit_for_bit() {
    use fuzzyq_sim::io::checkpoint::{Checkpoint, RunState};
    if gpu().is_none() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // What is tested is the state's way through the file and back onto the device.
    let policy = pointmass_small();
    let mut value = policy.clone();
    value.solver.evaluation_sweeps = 0;
    for (what, mut c) in [("policy", policy), ("value", value)] {
        c.solver.device = Device::Gpu;
        let mut saved = Vec::new();
        let whole = fuzzyq_sim::train::train_showing(&c, None, true, |p, s| {
            if let Some(s) = s.filter(|_| [2, 5].contains(&p.record.sweep)) {
                let path = dir.path().join(format!("{what}-{}.ckpt", p.record.sweep));
                let state = RunState::Fqi(s.borrowed());
                let checkpoint = Checkpoint {
                    settings: what.into(),
                    state,
                };
                checkpoint.save(&path).unwrap();
                saved.push(path);
            }
            ControlFlow::Continue(())
        })
        .unwrap();
        assert_eq!(saved.len(), 2, "{what} iteration: checkpoints written");
        for path in saved {
            let RunState::Fqi(state) = Checkpoint::load(&path).unwrap().state else {
                unreachable!("a fuzzy Q-iteration checkpoint")
            };
            let continued = fuzzyq_sim::train::train_showing(&c, Some(state), false, |_, _| {
                ControlFlow::Continue(())
            })
            .unwrap();
            let at = path.display();
            assert_eq!(continued.values, whole.values, "{at}: V");
            assert_eq!(continued.greedy, whole.greedy, "{at}: greedy actions");
            assert_eq!(continued.summary.sweeps, whole.summary.sweeps, "{at}");
        }
    }
}

/// A model that says when its reward is first asked for (the operator's preparation computes
/// the rewards), and is otherwise `inner`.
struct Announcing<M> {
    inner: M,
    first_reward: std::sync::Mutex<Option<std::sync::mpsc::Sender<()>>>,
}

impl<M: Model<f32>> Model<f32> for Announcing<M> {
    fn state_dim(&self) -> usize {
        self.inner.state_dim()
    }
    fn n_agents(&self) -> usize {
        self.inner.n_agents()
    }
    fn action_set(&self, agent: usize) -> fuzzyq_core::ActionSet<'_, f32> {
        self.inner.action_set(agent)
    }
    fn state_bounds(&self, dim: usize) -> (f32, f32) {
        self.inner.state_bounds(dim)
    }
    fn step(&self, x: &[f32], u: &[f32], next: &mut [f32]) {
        self.inner.step(x, u, next);
    }
    fn reward(&self, x: &[f32], u: &[f32]) -> f32 {
        if let Some(tx) = self.first_reward.lock().unwrap().take() {
            let _ = tx.send(());
        }
        self.inner.reward(x, u)
    }
    fn reward_depends_on_action(&self) -> bool {
        self.inner.reward_depends_on_action()
    }
    fn is_goal(&self, x: &[f32]) -> bool {
        self.inner.is_goal(x)
    }
    fn is_terminal(&self, x: &[f32]) -> bool {
        self.inner.is_terminal(x)
    }
    fn has_terminal_states(&self) -> bool {
        self.inner.has_terminal_states()
    }
    fn n_blocks(&self) -> usize {
        self.inner.n_blocks()
    }
    fn tabulated(&self) -> Option<fuzzyq_core::Tabulated<'_, f32>> {
        self.inner.tabulated()
    }
    fn reward_table(&self) -> Option<&[f32]> {
        self.inner.reward_table()
    }
    fn block_rows(&self, b: usize) -> Option<fuzzyq_core::BlockRows<'_, f32>> {
        self.inner.block_rows(b)
    }
    fn block(&self, b: usize) -> fuzzyq_core::Block<'_> {
        self.inner.block(b)
    }
}

/// Regression: `train --device gpu` opens the process's GPU on a thread of its own so that
/// the open overlaps the run's set-up on the host, but the solve waited for the GPU
/// (`Gpu::shared`) before preparing its operator, so the open preceded the set-up instead (on
/// the H200's host: 0.17-0.3 s added to every run). `solve_shared` waits for it only to make
/// the backend: here the open's last step waits for the model's first reward, which the
/// preparation computes; before the fix the solve waited for the open, which gave up waiting
/// after 30 s.
#[test]
fn the_gpu_opened_in_the_background_overlaps_the_set_up() {
    use std::sync::mpsc;
    let Some(g) = gpu() else { return };
    let c = pointmass_small();
    let (tx, rx) = mpsc::channel();
    let model = Announcing {
        inner: c.build_model().expect("model"),
        first_reward: std::sync::Mutex::new(Some(tx)),
    };
    let grid = c.grid::<f32>().expect("grid");
    let config = c.solver.solver_config();
    let (seen_tx, seen) = mpsc::channel();
    let opening = Gpu::open_shared_in_background(move |_| {
        let _ = seen_tx.send(rx.recv_timeout(std::time::Duration::from_secs(30)).is_ok());
    });
    // The run as `train` makes it.
    let shared = <f32 as fuzzyq_sim::train::DeviceReal>::solve_on_device(
        Device::Gpu,
        &model,
        &grid,
        &config,
        None,
        false,
        noop,
    )
    .unwrap();
    opening.wait().unwrap();
    assert!(
        seen.recv().unwrap(),
        "the run's operator was prepared while the GPU opened"
    );
    // The same run as on the GPU given.
    let given = fuzzyq_gpu::solve_from(g, &model, &grid, &config, None, false, noop).unwrap();
    assert_same(&shared, &given, "the shared GPU against the one given");
}
