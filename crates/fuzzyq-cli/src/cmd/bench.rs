//! `fuzzyq bench`: what this machine is, and how well the solver runs on it.
//!
//! Prints the CPU, its caches (as the OS reports them), the kernel instances it runs, the
//! fused multiply-add peak measured with the chosen instance, and the time of the solver's
//! full backups on a problem (the paper's grid by default), as multiply-adds per second and as
//! a fraction of the peak.
//!
//! A shared host's speed drifts (by more than 10% within minutes on the VMs this was measured
//! on), so a peak measured once and backups timed later can meet in different phases of it.
//! The peak is therefore also measured between the backups, briefly, after every sweep, and
//! each backup is set against the mean of the peaks measured just before and just after it:
//! the fraction reported is the median of those ratios.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use fuzzyq_core::NamedOption;
use fuzzyq_core::solver::{self, Device, Kernel, Precision};
use fuzzyq_sim::train;
use serde::Serialize;

use super::{TaskArgs, start_pool};
use crate::output::{self, write_json};

#[derive(Args, Debug)]
pub(crate) struct BenchArgs {
    /// The problem timed.
    #[command(flatten)]
    task: TaskArgs,
    /// Kernel instance (default: the fastest this CPU runs).
    #[arg(long, value_parser = output::named::<Kernel>())]
    kernel: Option<Kernel>,
    /// Solver precision (default: the configuration's).
    #[arg(long, value_parser = output::named::<Precision>())]
    precision: Option<Precision>,
    /// Worker threads (default: one per core).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// Full backups timed (after a first one that is not).
    #[arg(long, value_name = "N", default_value_t = 4)]
    backups: usize,
    /// Seconds of the first fused multiply-add peak measurement (a quarter of it is measured
    /// again after every sweep, to set each backup against the peak around it).
    #[arg(long, value_name = "S", default_value_t = 1.0)]
    peak_seconds: f64,
    /// Also write the results as JSON.
    #[arg(long, value_name = "FILE.json")]
    json: Option<PathBuf>,
    /// Time the backups on the CPU (default) or on the GPU (the adapter, its measured FMA
    /// peak and a full backup's share of it).
    #[arg(long, value_parser = output::named::<Device>(), default_value = "cpu")]
    device: Device,
    /// With --device gpu: evaluation sweeps timed after the backups, under the greedy actions
    /// of a further full backup [default: 3; 0 skips both, for problems whose backups take
    /// long].
    #[arg(long, value_name = "N")]
    evaluations: Option<usize>,
    /// Refuse problems estimated to need more memory than GB gigabytes on this machine
    /// [default: 90% of its memory].
    #[arg(long, value_name = "GB", allow_hyphen_values = true)]
    max_memory: Option<f64>,
}

/// One cache level as the OS reports it.
#[derive(Debug, Serialize)]
struct Cache {
    level: u32,
    kind: String,
    bytes: u64,
    /// Logical CPUs sharing it.
    shared_by: usize,
}

/// The `--json` output.
#[derive(Debug, Serialize)]
struct Report {
    #[serde(flatten)]
    machine: Machine,
    kernel: &'static str,
    precision: &'static str,
    peak_gfma_per_second: f64,
    env: &'static str,
    cores: usize,
    joint_actions: usize,
    backup: String,
    multiply_adds_per_backup: Option<f64>,
    /// The peak measured again after each sweep (the first, untimed one included).
    peaks_between_backups: Vec<f64>,
    backup_seconds: Vec<f64>,
    median_backup_seconds: f64,
    gfma_per_second: Option<f64>,
    /// Each backup's multiply-adds per second over the mean of the peaks measured just
    /// before and just after it.
    fractions_of_peak: Option<Vec<f64>>,
    /// The median of `fractions_of_peak`.
    fraction_of_peak: Option<f64>,
}

pub(crate) fn run(args: BenchArgs) -> anyhow::Result<()> {
    if args.backups == 0 {
        anyhow::bail!("--backups must be at least 1");
    }
    if !(args.peak_seconds > 0.0 && args.peak_seconds <= 60.0) {
        anyhow::bail!(
            "--peak-seconds must be in (0, 60], got {}",
            args.peak_seconds
        );
    }
    output::plan(
        &[(args.json.as_deref(), "--json")],
        &[(args.task.config.as_deref(), "--config")],
    )?;
    let mut config = args.task.load()?;
    let estimate = fuzzyq_sim::memory::bench(&config, args.device == Device::Gpu);
    output::check_memory(args.max_memory, &estimate)?;
    start_pool(args.threads)?;
    if args.evaluations.is_some() && args.device != Device::Gpu {
        anyhow::bail!("--evaluations times the GPU's evaluation sweeps; it needs --device gpu");
    }
    if args.device == Device::Gpu {
        if args.kernel.is_some() {
            anyhow::bail!("--kernel chooses a CPU kernel; --device gpu has none");
        }
        return run_gpu(&args, config);
    }
    let kernel = args.kernel.unwrap_or_else(Kernel::best);
    if !kernel.is_available() {
        anyhow::bail!("this CPU cannot run --kernel {}", kernel.name());
    }
    // Plain value-iteration sweeps: each one a full backup over every core and joint action.
    let s = &mut config.solver;
    s.kernel = Some(kernel);
    s.precision = args.precision.unwrap_or(s.precision);
    s.max_sweeps = args.backups + 1;
    s.xi = f64::MIN_POSITIVE;
    s.extrapolate = false;
    s.evaluation_sweeps = 0;
    config.validate()?;

    let machine = Machine::here(kernel);
    let precision = config.solver.precision;
    let measure_peak = |seconds: f64| match precision {
        Precision::F32 => solver::fma_peak::<f32>(Some(kernel), seconds),
        Precision::F64 => solver::fma_peak::<f64>(Some(kernel), seconds),
    };
    let peak = measure_peak(args.peak_seconds).context("the kernel instance is not available")?;
    println!(
        "FMA peak   {:.1} GFMA/s ({} {}, {} threads, {} s)",
        peak.gfma_per_second,
        peak.kernel,
        precision.name(),
        peak.threads,
        args.peak_seconds
    );
    let timed = Backups::time(&config, args.backups, || {
        measure_peak(args.peak_seconds / 4.0).map_or(f64::NAN, |p| p.gfma_per_second)
    })?;
    timed.print(&config, args.peak_seconds / 4.0);
    if let Some(path) = &args.json {
        let (cores, joint) = (config.n_cores(), config.n_joint_actions());
        let report = Report {
            machine,
            kernel: kernel.name(),
            precision: precision.name(),
            peak_gfma_per_second: peak.gfma_per_second,
            env: config.env.name(),
            cores,
            joint_actions: joint,
            backup: timed.backup,
            multiply_adds_per_backup: timed.multiply_adds,
            peaks_between_backups: timed.around,
            backup_seconds: timed.times,
            median_backup_seconds: timed.median_seconds,
            gfma_per_second: timed.rate,
            fractions_of_peak: timed.fractions,
            fraction_of_peak: timed.fraction,
        };
        write_json(path, &report)?;
    }
    Ok(())
}

/// This machine as `bench` reports it: the CPU, its vector features, caches and kernel
/// instances (printed when gathered).
#[derive(Debug, Serialize)]
struct Machine {
    cpu: String,
    logical_cpus: usize,
    threads: usize,
    features: Vec<&'static str>,
    caches: Vec<Cache>,
    kernels: Vec<&'static str>,
}

impl Machine {
    /// Gathers and prints what this machine is, and the `kernel` instance timed.
    fn here(kernel: Kernel) -> Self {
        let m = Self {
            cpu: cpu_name(),
            logical_cpus: std::thread::available_parallelism().map_or(1, usize::from),
            threads: rayon::current_num_threads(),
            features: features(),
            caches: caches(),
            kernels: Kernel::ALL
                .iter()
                .filter(|k| k.is_available())
                .map(|k| k.name())
                .collect(),
        };
        println!(
            "cpu        {} ({} logical CPUs, {} threads used)",
            m.cpu, m.logical_cpus, m.threads
        );
        println!(
            "features   {}",
            if m.features.is_empty() {
                "none of avx512f, avx512vl, avx2, fma".to_string()
            } else {
                m.features.join(" ")
            }
        );
        println!("caches     {}", fmt_caches(&m.caches));
        println!(
            "kernels    {} (fastest first); timing {}",
            m.kernels.join(", "),
            kernel.name()
        );
        m
    }
}

/// Full backups timed, each set against the peak measured just before and just after it.
struct Backups {
    /// The backup path (`block` or `generic`).
    backup: String,
    multiply_adds: Option<f64>,
    /// The peak measured after each sweep (the first, untimed one included).
    around: Vec<f64>,
    /// Each timed backup's seconds.
    times: Vec<f64>,
    median_seconds: f64,
    /// Billions of multiply-adds per second at the median time.
    rate: Option<f64>,
    fractions: Option<Vec<f64>>,
    fraction: Option<f64>,
}

impl Backups {
    /// Solves `config` (plain sweeps, `backups + 1` of them), measuring the peak with `peak`
    /// after every sweep; the first sweep (the set-up, from `V = 0`) is not timed.
    fn time(
        config: &fuzzyq_sim::TrainConfig,
        backups: usize,
        mut peak: impl FnMut() -> f64,
    ) -> anyhow::Result<Self> {
        eprintln!(
            "timing {} full backups of {}: {} cores x {} joint actions ...",
            backups + 1,
            config.env.name(),
            config.n_cores(),
            config.n_joint_actions()
        );
        let start = Instant::now();
        // After every sweep: its end on the solve's clock, then the peak again, and how long
        // that measurement took (the solve's clock runs on through it).
        let (mut ends, mut around, mut spent) = (Vec::new(), Vec::new(), Vec::new());
        let artifact = train::train(config, |p| {
            ends.push(p.record.seconds);
            let t0 = Instant::now();
            around.push(peak());
            spent.push(t0.elapsed().as_secs_f64());
            std::ops::ControlFlow::Continue(())
        })?;
        let summary = artifact.summary;
        // Sweep k's time is the gap between the end of sweep k - 1 and its own, less the
        // peak measured in between.
        let times: Vec<f64> = (1..ends.len())
            .map(|k| ends[k] - ends[k - 1] - spent[k - 1])
            .collect();
        if times.is_empty() {
            anyhow::bail!(
                "the solve stopped after {} sweep(s) (its values did not change): no full backup to time",
                ends.len()
            );
        }
        let median_seconds = median(&times);
        let fma = summary.multiply_adds_per_sweep;
        let fractions = fma.map(|f| {
            (1..ends.len())
                .map(|k| f / times[k - 1] / 1e9 / (0.5 * (around[k - 1] + around[k])))
                .collect::<Vec<_>>()
        });
        eprintln!(
            "(run {:.1} s including set-up and the final greedy pass)",
            start.elapsed().as_secs_f64()
        );
        Ok(Self {
            backup: summary.backup,
            multiply_adds: fma,
            around,
            rate: fma.map(|f| f / median_seconds / 1e9),
            fraction: fractions.as_deref().map(median),
            fractions,
            times,
            median_seconds,
        })
    }

    /// Prints the problem, the peaks between the sweeps (of `peak_seconds` each) and the
    /// backups.
    fn print(&self, config: &fuzzyq_sim::TrainConfig, peak_seconds: f64) {
        println!(
            "problem    {}: {} cores x {} joint actions, {} path{}",
            config.env.name(),
            config.n_cores(),
            config.n_joint_actions(),
            self.backup,
            self.multiply_adds.map_or(String::new(), |f| format!(
                ", {f:.3e} multiply-adds per full backup"
            )),
        );
        let (lo, hi) = min_max(&self.around);
        println!(
            "           {lo:.1}-{hi:.1} GFMA/s in the {} measurements of {peak_seconds} s between the sweeps",
            self.around.len(),
        );
        println!(
            "backup     {:.3} s median of {} full backups (value iteration from V = 0){}",
            self.median_seconds,
            self.times.len(),
            match (self.rate, &self.fractions, self.fraction) {
                (Some(r), Some(fs), Some(f)) => {
                    let (lo, hi) = min_max(fs);
                    format!(
                        ": {r:.1} GFMA/s, {:.0}% of the peak measured around each backup \
                         (median; {:.0}-{:.0}%)",
                        100.0 * f,
                        100.0 * lo,
                        100.0 * hi
                    )
                }
                _ => " (the generic path: no multiply-add count)".to_string(),
            }
        );
        eprintln!(
            "(early sweeps from V = 0; full backups of a nearly converged V can take longer: see \
             BENCHMARKS.md)"
        );
    }
}

/// The `--json` output of `--device gpu`.
#[derive(Debug, Serialize)]
struct GpuReport {
    adapter: String,
    backend: String,
    driver: String,
    fused_fma: bool,
    /// Seconds to open the GPU: the device, the generic kernels, the probes.
    opening_seconds: [f64; 3],
    /// The adapter's memory for a run's buffers, where the API reports it.
    memory_bytes: Option<u64>,
    /// What the timed run's buffers took on the device.
    run_bytes: u64,
    peak_gfma_per_second: f64,
    env: &'static str,
    cores: usize,
    joint_actions: usize,
    multiply_adds_per_backup: Option<f64>,
    /// How a full pass is batched: each batch fixes the cores of the first `batch_level`
    /// contracted blocks and runs `items_per_batch` cores of the next (level 0: slabs).
    batch_level: usize,
    items_per_batch: u64,
    batches_per_pass: u64,
    /// The buffers `V` and the other per-core buffers are cut into, each within one storage
    /// binding (1 unless `V` exceeds a binding).
    v_parts: usize,
    setup_seconds: f64,
    /// Of the set-up, the seconds the driver took to compile the problem's kernels.
    compile_seconds: f64,
    subgroups: bool,
    /// The fused last stage's kernel (`last1`: rows one at a time, `lastm`: merged, `lastw`:
    /// from workgroup memory, `lastu`: the rows compiled in), if the problem has one
    /// (`FUZZYQ_GPU_LAST`).
    last_stage: Option<&'static str>,
    /// The kernel of each stage before it (`stage_c`: a thread per element, `stage_m`: a
    /// block core's rows merged, `stage_u`: the block's rows compiled in;
    /// `FUZZYQ_GPU_STAGES`).
    stage_kernels: Vec<&'static str>,
    /// wgpu's runtime checks the kernels were compiled with (`none` by default, `all`, or
    /// some of `zero`, `loops`, `division` and `bounds`; `FUZZYQ_GPU_CHECKS`).
    runtime_checks: String,
    evaluation_seconds: Vec<f64>,
    /// The stages of a full backup an evaluation sweep runs for every action before a thread
    /// per core nests the other blocks (`FUZZYQ_GPU_EVAL`).
    evaluation_stages: usize,
    /// Seconds reading `V` and the greedy actions back to the host (a run's last step).
    readback_seconds: f64,
    backup_seconds: Vec<f64>,
    median_backup_seconds: f64,
    gfma_per_second: Option<f64>,
    fraction_of_peak: Option<f64>,
}

/// One more full backup from `v` into `out`, and where `evaluate` one more evaluation sweep
/// from `out` into `v` (under the greedy actions the timed sweeps left), with every dispatch
/// timed on its own (`FUZZYQ_GPU_PROFILE`), printed per kernel.
fn profile_passes(
    sweeps: &mut fuzzyq_gpu::GpuSweeps,
    v: fuzzyq_core::solver::Buf,
    out: fuzzyq_core::solver::Buf,
    evaluate: bool,
) -> anyhow::Result<()> {
    use fuzzyq_core::solver::Sweeps;
    let print = |sweeps: &fuzzyq_gpu::GpuSweeps, pass: &str| {
        for (kernel, seconds, n) in sweeps.profile() {
            println!(
                "profile    {pass}{kernel}: {:.3} ms in {n} dispatches",
                1e3 * seconds
            );
        }
    };
    sweeps.set_profiling(true);
    sweeps.backup(v, out)?;
    print(sweeps, "");
    if evaluate {
        sweeps.set_profiling(true);
        sweeps.evaluate(out, v)?;
        print(sweeps, "evaluation: ");
    }
    sweeps.set_profiling(false);
    Ok(())
}

/// `fuzzyq bench --device gpu`: the adapter, its FMA peak, and full backups on it.
fn run_gpu(args: &BenchArgs, config: fuzzyq_sim::io::config::TrainConfig) -> anyhow::Result<()> {
    use fuzzyq_core::solver::{Buf, Sweeps};
    if args.precision.is_some_and(|p| p != Precision::F32) {
        anyhow::bail!("--device gpu runs in f32");
    }
    let gpu = fuzzyq_gpu::Gpu::shared()?;
    let a = gpu.summary().clone();
    println!(
        "gpu        {} ({}, {}); fma {}; f64 in shaders: {}; {}; opened in {:.3} s (device \
         {:.3} s, generic kernels {:.3} s, probes {:.3} s)",
        a.name,
        a.backend,
        a.driver,
        if a.fused_fma { "fused" } else { "not fused" },
        if a.f64 { "yes" } else { "no" },
        gpu_memory(a.memory),
        a.opening.device + a.opening.kernels + a.opening.probes,
        a.opening.device,
        a.opening.kernels,
        a.opening.probes
    );
    let peak = gpu.fma_peak(args.peak_seconds)?;
    println!(
        "FMA peak   {peak:.1} GFMA/s (f32, best of {} s of dispatches)",
        args.peak_seconds
    );
    let model = config.build_model()?;
    let grid = config.grid::<f32>()?;
    let s = config.solver.solver_config();
    let backup = fuzzyq_core::backup::Backup {
        gamma: s.gamma as f32,
        absorbing_goal: s.absorbing_goal,
    };
    let t0 = Instant::now();
    let op = solver::Operator::new(&model, grid.view(), backup, s.path)?;
    // The buffers the timed passes use: `V` twice and the policy.
    let scheme = solver::Scheme::ModifiedPolicy;
    let mut sweeps = fuzzyq_gpu::GpuSweeps::for_scheme(&gpu, &op, scheme)?;
    let setup = t0.elapsed().as_secs_f64();
    let (cores, joint) = (config.n_cores(), config.n_joint_actions());
    let fma = op.multiply_adds_per_sweep();
    eprintln!(
        "timing {} full backups of {}: {cores} cores x {joint} joint actions ...",
        args.backups + 1,
        config.env.name()
    );
    // From V = 0, then each backup's output is the next one's input.
    let mut times = Vec::with_capacity(args.backups);
    let (mut v, mut out) = (Buf(0), Buf(1));
    for k in 0..=args.backups {
        let t = Instant::now();
        sweeps.backup(v, out)?;
        if k > 0 {
            times.push(t.elapsed().as_secs_f64());
        }
        (v, out) = (out, v);
    }
    let median_seconds = median(&times);
    let rate = fma.map(|f| f / median_seconds / 1e9);
    let fraction = rate.map(|r| r / peak);
    // Evaluation sweeps (modified policy iteration's) under the greedy actions of the last V.
    let mut evaluation = Vec::new();
    let evaluations = args.evaluations.unwrap_or(3);
    if evaluations > 0 && op.block_plan().is_some_and(|p| p.can_evaluate) {
        sweeps.backup_greedy(v, out)?;
        for _ in 0..evaluations {
            let t = Instant::now();
            sweeps.evaluate(out, v)?;
            evaluation.push(t.elapsed().as_secs_f64());
        }
        let nb = op.block_plan().map_or(0, |p| p.tables.len());
        println!(
            "evaluate   {:.4} s median of {} evaluation sweeps ({}){}",
            median(&evaluation),
            evaluation.len(),
            match sweeps.evaluation_stages() {
                0 => "every block nested per core".to_string(),
                k => format!(
                    "{k} stage(s) for every action, then {} block(s) per core",
                    nb - k
                ),
            },
            if sweeps.uses_subgroups() {
                "; the last stage reduces by subgroup shuffles"
            } else {
                ""
            }
        );
    }
    // What a run does at its end: V and the greedy actions back to the host.
    let t = Instant::now();
    sweeps.values(v)?;
    sweeps.policy()?;
    let readback_seconds = t.elapsed().as_secs_f64();
    println!("read back  {readback_seconds:.4} s for V and the greedy actions");
    if std::env::var("FUZZYQ_GPU_PROFILE").is_ok_and(|v| !v.is_empty() && v != "0") {
        profile_passes(&mut sweeps, v, out, !evaluation.is_empty())?;
    }
    println!(
        "problem    {}: {cores} cores x {joint} joint actions{}; {}{}{}{}; {:.3} GB on the GPU; \
         set-up {:.3} s (compiling kernels {:.3} s)",
        config.env.name(),
        fma.map_or(String::new(), |f| format!(
            ", {f:.3e} multiply-adds per full backup"
        )),
        sweeps.batches(),
        match sweeps.parts() {
            1 => String::new(),
            p => format!("; V in {p} parts"),
        },
        sweeps
            .last_stage()
            .map_or(String::new(), |k| format!("; last stage {k}")),
        match gpu.checks() {
            fuzzyq_gpu::Checks::NONE => String::new(),
            c => format!("; wgpu's runtime checks: {c}"),
        },
        sweeps.device_bytes() as f64 / 1e9,
        setup,
        sweeps.compile_seconds()
    );
    let (lo, hi) = min_max(&times);
    println!(
        "backup     {:.4} s median of {} full backups ({lo:.4}-{hi:.4} s){}",
        median_seconds,
        times.len(),
        match (rate, fraction) {
            (Some(r), Some(f)) => format!(": {r:.1} GFMA/s, {:.1}% of the peak", 100.0 * f),
            _ => String::new(),
        }
    );
    if let Some(path) = &args.json {
        let report = GpuReport {
            adapter: a.name,
            backend: a.backend,
            driver: a.driver,
            fused_fma: a.fused_fma,
            opening_seconds: [a.opening.device, a.opening.kernels, a.opening.probes],
            memory_bytes: a.memory,
            run_bytes: sweeps.device_bytes(),
            peak_gfma_per_second: peak,
            env: config.env.name(),
            cores,
            joint_actions: joint,
            multiply_adds_per_backup: fma,
            batch_level: sweeps.batches().level,
            items_per_batch: sweeps.batches().items,
            batches_per_pass: sweeps.batches().count,
            v_parts: sweeps.parts(),
            setup_seconds: setup,
            compile_seconds: sweeps.compile_seconds(),
            subgroups: sweeps.uses_subgroups(),
            last_stage: sweeps.last_stage(),
            stage_kernels: sweeps.stage_kernels(),
            runtime_checks: gpu.checks().to_string(),
            evaluation_seconds: evaluation,
            evaluation_stages: sweeps.evaluation_stages(),
            readback_seconds,
            backup_seconds: times,
            median_backup_seconds: median_seconds,
            gfma_per_second: rate,
            fraction_of_peak: fraction,
        };
        write_json(path, &report)?;
    }
    Ok(())
}

/// The adapter's memory in words: `"141.05 GB free"`, or that the API does not say.
pub(crate) fn gpu_memory(bytes: Option<u64>) -> String {
    bytes.map_or_else(
        || "free memory unknown (the API does not report it)".to_string(),
        |b| format!("{:.2} GB free", b as f64 / 1e9),
    )
}

fn median(xs: &[f64]) -> f64 {
    let mut v = xs.to_vec();
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => 0.5 * (v[n / 2 - 1] + v[n / 2]),
    }
}

/// The smallest and largest of `xs` (`(inf, -inf)` for none).
fn min_max(xs: &[f64]) -> (f64, f64) {
    xs.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
            (lo.min(x), hi.max(x))
        })
}

/// The CPU's model name (Linux `/proc/cpuinfo`), or the architecture elsewhere.
fn cpu_name() -> String {
    std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|t| {
            t.lines()
                .find(|l| l.starts_with("model name"))
                .and_then(|l| l.split_once(':'))
                .map(|(_, v)| v.trim().to_string())
        })
        .unwrap_or_else(|| std::env::consts::ARCH.to_string())
}

/// The vector features the kernels use, as this CPU reports them.
fn features() -> Vec<&'static str> {
    #[allow(unused_mut)] // empty off x86-64
    let mut out = Vec::new();
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx512f") {
            out.push("avx512f");
        }
        if std::arch::is_x86_feature_detected!("avx512vl") {
            out.push("avx512vl");
        }
        if std::arch::is_x86_feature_detected!("avx2") {
            out.push("avx2");
        }
        if std::arch::is_x86_feature_detected!("fma") {
            out.push("fma");
        }
    }
    out
}

/// The caches of CPU 0 (Linux `/sys/devices/system/cpu/cpu0/cache`); empty elsewhere.
fn caches() -> Vec<Cache> {
    let dir = Path::new("/sys/devices/system/cpu/cpu0/cache");
    let mut out = Vec::new();
    for i in 0..8 {
        let d = dir.join(format!("index{i}"));
        let read = |f: &str| std::fs::read_to_string(d.join(f)).ok();
        let (Some(level), Some(kind), Some(size)) = (read("level"), read("type"), read("size"))
        else {
            continue;
        };
        let Some(bytes) = parse_size(size.trim()) else {
            continue;
        };
        out.push(Cache {
            level: level.trim().parse().unwrap_or(0),
            kind: kind.trim().to_string(),
            bytes,
            shared_by: read("shared_cpu_list").map_or(1, |l| count_cpus(l.trim())),
        });
    }
    out
}

/// `"32K"`, `"512K"`, `"32768K"`, `"8M"` in bytes.
fn parse_size(s: &str) -> Option<u64> {
    let (n, unit) = s.split_at(s.find(|c: char| !c.is_ascii_digit()).unwrap_or(s.len()));
    let n: u64 = n.parse().ok()?;
    Some(match unit {
        "" => n,
        "K" => n << 10,
        "M" => n << 20,
        "G" => n << 30,
        _ => return None,
    })
}

/// The number of CPUs in a list such as `"0-3,8"`.
fn count_cpus(list: &str) -> usize {
    list.split(',')
        .filter(|p| !p.is_empty())
        .map(|p| match p.split_once('-') {
            Some((a, b)) => match (a.parse::<usize>(), b.parse::<usize>()) {
                (Ok(a), Ok(b)) if b >= a => b - a + 1,
                _ => 1,
            },
            None => 1,
        })
        .sum()
}

fn fmt_caches(caches: &[Cache]) -> String {
    if caches.is_empty() {
        return "not reported by the OS".to_string();
    }
    caches
        .iter()
        .map(|c| {
            let kind = match c.kind.as_str() {
                "Data" => "d",
                "Instruction" => "i",
                _ => "",
            };
            let size = if c.bytes >= 1 << 20 && c.bytes % (1 << 20) == 0 {
                format!("{} MiB", c.bytes >> 20)
            } else {
                format!("{} KiB", c.bytes >> 10)
            };
            let shared = if c.shared_by > 1 {
                format!(" per {} CPUs", c.shared_by)
            } else {
                String::new()
            };
            format!("L{}{kind} {size}{shared}", c.level)
        })
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cache_sizes_and_cpu_lists_parse() {
        assert_eq!(parse_size("32K"), Some(32 << 10));
        assert_eq!(parse_size("8M"), Some(8 << 20));
        assert_eq!(parse_size("512"), Some(512));
        assert_eq!(parse_size("12Q"), None);
        assert_eq!(count_cpus("0-3,8"), 5);
        assert_eq!(count_cpus("1"), 1);
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
    }
}
