//! `fuzzyq train`.

use std::io::IsTerminal;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use clap::Args;
use fuzzyq_core::additive::Update;
use fuzzyq_core::solver::{
    BackupPath, Device, IterationOperator, Kernel, Precision, Progress, Scheme, SolveError,
    SweepMode,
};
use fuzzyq_sim::io::checkpoint::{FqiState, RunState};
use fuzzyq_sim::io::config::{EnvConfig, SolverOverrides};
use fuzzyq_sim::io::policy_file::{PolicyArtifact, PolicyFile, TrainSummary};
use fuzzyq_sim::io::transitions::read_transitions_csv;
use fuzzyq_sim::learn::fql::EpisodeRecord;
use fuzzyq_sim::model::F64Model;
use fuzzyq_sim::train::{self, Learner, SampleLearning, SampleOptions};
use fuzzyq_sim::{SimError, TrainConfig};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;

use super::checkpoints::{Checkpoints, Episodes};
use super::{TaskArgs, start_pool};
use crate::Failure;
use crate::output::{self, refuse, write_json};
use crate::plot;

#[derive(Args, Debug)]
pub(crate) struct TrainArgs {
    #[command(flatten)]
    task: TaskArgs,
    /// Discount factor in [0, 1).
    #[arg(long, value_name = "G")]
    gamma: Option<f64>,
    /// Stop when the sweep's change ||theta_{k+1} - theta_k||_inf is at most X.
    #[arg(long, value_name = "X")]
    xi: Option<f64>,
    /// Sweep limit: every sweep counts, full backups and evaluation sweeps alike (the last
    /// one allowed is a full backup).
    #[arg(long, value_name = "K")]
    max_sweeps: Option<usize>,
    /// The iteration.
    #[arg(long, value_parser = output::named::<IterationOperator>())]
    operator: Option<IterationOperator>,
    /// Asynchronous (Gauss-Seidel) sweeps instead of synchronous ones.
    #[arg(long = "async")]
    asynchronous: bool,
    /// Goal states collect their reward and have zero future value.
    #[arg(long)]
    absorbing_goal: bool,
    /// Extrapolate synchronous sweeps with MacQueen's bounds (fewer sweeps, same stopping
    /// rule and error bound).
    #[arg(long, overrides_with = "no_extrapolate")]
    extrapolate: bool,
    /// Plain sweeps from theta_0 = 0, as in the paper.
    #[arg(long)]
    no_extrapolate: bool,
    /// Modified policy iteration: at most N policy-evaluation sweeps after each full backup
    /// (default 5; 0 = value iteration, one full backup per sweep, as in the paper).
    #[arg(long, value_name = "N")]
    evaluation_sweeps: Option<usize>,
    /// Start modified policy iteration from the solution on the grid with every other core,
    /// interpolated (same stopping rule and error bound, fewer sweeps on fine grids; the
    /// robots' default).
    #[arg(long, overrides_with = "no_coarse_start")]
    coarse_start: bool,
    /// Start from V = 0 (the point masses' default).
    #[arg(long)]
    no_coarse_start: bool,
    /// Backup implementation.
    #[arg(long, value_parser = output::named::<BackupPath>())]
    backup: Option<BackupPath>,
    /// Solver precision.
    #[arg(long, value_parser = output::named::<Precision>())]
    precision: Option<Precision>,
    /// Kernel instance of the block backup (default: the fastest this CPU runs; all give
    /// identical results).
    #[arg(long, value_parser = output::named::<Kernel>())]
    kernel: Option<Kernel>,
    /// Where the sweeps compute: cpu, or gpu (the block path in f32 through wgpu; the CPU's
    /// values and greedy actions bit for bit where the adapter fuses multiply-adds).
    #[arg(long, value_parser = output::named::<Device>())]
    device: Option<Device>,
    /// Worker threads (default: one per core; results do not depend on it).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// The arena of the khepera environment (TOML with walls and obstacles); replaces the
    /// config's `[env.arena]`.
    #[arg(long, value_name = "FILE.toml")]
    arena: Option<PathBuf>,
    /// The learner: joint fuzzy Q-iteration on the model, or a learner from samples (fql:
    /// on the point masses' own states or the robots' sonars; vqql: point masses).
    #[arg(long, value_parser = output::named::<Learner>(), default_value = "fqi")]
    learner: Learner,
    /// learned-model: transitions to collect on the plant (random actions from seeded starts)
    /// [default: 20000].
    #[arg(long, value_name = "N", conflicts_with = "transitions")]
    samples: Option<usize>,
    /// learned-model: rounds of collection. After the first (random actions), each round
    /// collects --samples more transitions epsilon-greedily with the policy solved so far,
    /// refits on all of them and solves again [default: 1].
    #[arg(long, value_name = "N", conflicts_with = "transitions")]
    rounds: Option<usize>,
    /// learned-model, with --rounds: probability of a random action per robot or agent and
    /// step in the rounds after the first [default: 0.1].
    #[arg(long, value_name = "E", requires = "rounds")]
    epsilon: Option<f64>,
    /// learned-model: learn from these logged transitions instead of collecting them: CSV, one
    /// transition per line, `x_1..x_E, u_1..u_D, x'_1..x'_E, r`, an optional header line.
    #[arg(long, value_name = "FILE.csv")]
    transitions: Option<PathBuf>,
    /// fql, vqql: number of episodes [default: 3000 for the point masses, 2000 for the
    /// robots].
    #[arg(long, value_name = "N")]
    episodes: Option<usize>,
    /// fql, vqql: the update as printed in the paper (eqs 24-26) instead of the corrected one.
    #[arg(long)]
    literal: bool,
    /// vqql: cells per agent [default: the own-state cores of the grid].
    #[arg(long, value_name = "K")]
    cells: Option<usize>,
    /// fql, vqql, learned-model: seed of exploration, starts and the plant's noise.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    /// fql, vqql: write the learning curve (one row per episode) as CSV.
    #[arg(long, value_name = "FILE.csv")]
    curve: Option<PathBuf>,
    /// fql, vqql: draw the learning curve (PNG or SVG).
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    plot: Option<PathBuf>,
    /// fqi, fql, vqql: write the run's state to FILE (atomically) every --checkpoint-every
    /// sweeps or episodes and when Ctrl-C stops it; --resume FILE continues from it.
    #[arg(long, value_name = "FILE")]
    checkpoint: Option<PathBuf>,
    /// With --checkpoint: sweeps (fqi) or episodes (fql, vqql) between checkpoints
    /// [default: 10 sweeps, 100 episodes].
    #[arg(long, value_name = "N", requires = "checkpoint")]
    checkpoint_every: Option<usize>,
    /// Continue the run whose state --checkpoint wrote to FILE: give the command that wrote
    /// it, plus --resume FILE. The policy is the uninterrupted run's, byte for byte.
    #[arg(long, value_name = "FILE")]
    resume: Option<PathBuf>,
    /// Where to write the policy file.
    #[arg(long, value_name = "POLICY")]
    out: PathBuf,
    /// Also write a JSON summary of the run.
    #[arg(long, value_name = "SUMMARY.json")]
    json: Option<PathBuf>,
    /// Refuse runs estimated to need more memory than GB gigabytes [default: 90% of this
    /// machine's memory].
    #[arg(long, value_name = "GB", allow_hyphen_values = true)]
    max_memory: Option<f64>,
    /// No progress output.
    #[arg(long, short)]
    quiet: bool,
}

/// The `--json` summary of fuzzy Q-iteration.
#[derive(Serialize)]
struct Summary<'a> {
    env: &'a str,
    policy: String,
    sweeps: usize,
    full_backups: usize,
    evaluation_sweeps: usize,
    converged: bool,
    delta_inf: f64,
    xi: f64,
    gamma: f64,
    error_bound: f64,
    sweep_bound: usize,
    seconds: f64,
    seconds_per_sweep: f64,
    cores: usize,
    joint_actions: usize,
    q_values: f64,
    backup: &'a str,
    kernel: &'a str,
    multiply_adds_per_sweep: Option<f64>,
    sweep_seconds: f64,
    evaluation_seconds: f64,
    /// The part of `seconds` before the first sweep, the coarse start aside: the operator
    /// (block tables, rewards) and the backend's buffers (on a GPU: kernels, tables, `V`).
    #[serde(skip_serializing_if = "Option::is_none")]
    setup_seconds: Option<f64>,
    /// The part of `seconds` bringing `V` and the greedy actions into grid order at the end
    /// (on a GPU: reading them back).
    #[serde(skip_serializing_if = "Option::is_none")]
    result_seconds: Option<f64>,
    #[serde(flatten)]
    timings: Timings,
    gflops_fma: Option<f64>,
    precision: Precision,
    sweep: SweepMode,
    absorbing_goal: bool,
    threads: usize,
    peak_memory_mb: Option<f64>,
    deltas: &'a [(f64, f64)],
    extrapolated: &'a [usize],
    /// The coarse start (`solver.coarse_start`): its grid's cores, its sweeps and the seconds
    /// of its solve and interpolation (part of `seconds`, not of `sweep_seconds`).
    #[serde(skip_serializing_if = "Option::is_none")]
    coarse_start: Option<CoarseSummary>,
    /// `--learner learned-model`: the data and the fit.
    #[serde(skip_serializing_if = "Option::is_none")]
    learned_model: Option<LearnedSummary<'a>>,
}

/// Where a run's time went outside the solver (`--json`).
#[derive(Clone, Copy, Serialize)]
struct Timings {
    /// `--device gpu`: seconds opening the GPU (the adapter, its start-up probes and the
    /// kernels every problem shares): before `seconds`, or beside its set-up
    /// (`device_beside_setup`).
    #[serde(skip_serializing_if = "Option::is_none")]
    device_seconds: Option<f64>,
    /// `--device gpu`: whether the GPU was opened on a thread of its own while the run was
    /// set up on the host ([`open_device`]), so that `device_seconds` overlap `seconds`.
    #[serde(skip_serializing_if = "Option::is_none")]
    device_beside_setup: Option<bool>,
    /// Seconds encoding the policy file and writing it (staged; put in place at the end).
    write_seconds: f64,
    /// Seconds from the start of the command to its policy file written: the configuration,
    /// the device, `seconds` and `write_seconds` (not the process's start).
    command_seconds: f64,
}

/// A run's sweeps for the closing line: `52 sweeps (10 full backups + 42 evaluation sweeps,
/// after a coarse start: 80 sweeps on 1185921 cores in 0.4 s)`; the kinds only where modified
/// policy iteration ran, the coarse start only where one did.
fn sweeps_done(s: &TrainSummary) -> String {
    let evaluation = s.evaluation.len();
    let mut parts = Vec::new();
    if evaluation > 0 {
        let full = s.sweeps - evaluation;
        parts.push(format!(
            "{} + {}",
            count(full, "full backup"),
            count(evaluation, "evaluation sweep")
        ));
    }
    if let Some(c) = s.coarse.as_deref() {
        parts.push(format!(
            "after a coarse start: {} on {} cores in {:.1} s",
            count(c.sweeps, "sweep"),
            c.cores,
            c.seconds
        ));
    }
    if parts.is_empty() {
        count(s.sweeps, "sweep")
    } else {
        format!("{} ({})", count(s.sweeps, "sweep"), parts.join(", "))
    }
}

/// `n` things, the noun in the plural unless `n` is 1.
fn count(n: usize, noun: &str) -> String {
    if n == 1 {
        format!("1 {noun}")
    } else {
        format!("{n} {noun}s")
    }
}

/// The `--json` part of a coarse start.
#[derive(Serialize)]
struct CoarseSummary {
    cores: usize,
    sweeps: usize,
    seconds: f64,
}

/// The `--json` part of `--learner learned-model`.
#[derive(Serialize)]
struct LearnedSummary<'a> {
    /// Where the transitions came from: `"plant"` or the `--transitions` file.
    source: String,
    samples: usize,
    /// The collection's seed (`None` for logged transitions).
    seed: Option<u64>,
    learning_seconds: f64,
    fit: &'a fuzzyq_sim::learn::fit::FitReport,
    table_error: &'a [fuzzyq_sim::learn::fit::TableError],
    /// Each round of collection, fit and solve (one without `--rounds`).
    rounds: &'a [train::Round],
    /// The rounds' exploration after the first (with `--rounds` above 1).
    #[serde(skip_serializing_if = "Option::is_none")]
    epsilon: Option<f64>,
}

/// The `--json` summary of a learner from samples.
#[derive(Serialize)]
struct SampleSummary {
    env: &'static str,
    learner: &'static str,
    update: Update,
    policy: String,
    episodes: usize,
    steps_total: usize,
    /// Episodes with a positive return: under the paper's reward, those that met it.
    rewarded_episodes: usize,
    converged_at: Option<usize>,
    final_eval_success_rate: Option<f64>,
    seconds: f64,
    seed: u64,
}

/// The configuration with every flag applied, validated.
fn build_config(args: &TrainArgs) -> anyhow::Result<TrainConfig> {
    let mut config = args.task.load()?;
    if let Some(path) = &args.arena {
        match &mut config.env {
            EnvConfig::Khepera(k) => k.arena = fuzzyq_sim::model::arena::Arena::from_file(path)?,
            _ => anyhow::bail!("--arena applies to --env khepera only"),
        }
    }
    solver_overrides(args).apply(&mut config.solver);
    config.validate()?;
    Ok(config)
}

/// The solver settings the flags set (the rest keep the configuration's values).
fn solver_overrides(args: &TrainArgs) -> SolverOverrides {
    // A `--no-` flag wins over its positive form, as the help's order reads.
    let either = |yes: bool, no: bool| match (yes, no) {
        (_, true) => Some(false),
        (true, false) => Some(true),
        (false, false) => None,
    };
    SolverOverrides {
        gamma: args.gamma,
        xi: args.xi,
        max_sweeps: args.max_sweeps,
        sweep: args.asynchronous.then_some(SweepMode::Asynchronous),
        absorbing_goal: args.absorbing_goal.then_some(true),
        backup: args.backup,
        precision: args.precision,
        extrapolate: either(args.extrapolate, args.no_extrapolate),
        evaluation_sweeps: args.evaluation_sweeps,
        coarse_start: either(args.coarse_start, args.no_coarse_start),
        kernel: args.kernel,
        operator: args.operator,
        device: args.device,
    }
}

/// Peak resident memory of this process (Linux `VmHWM`), in MB.
fn peak_memory_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb / 1024.0)
}

fn fmt_delta(p: &Progress) -> String {
    let d = p.record.delta;
    if p.record.evaluation {
        return format!("evaluation, half-span {:.4}", d.lower);
    }
    if p.record.extrapolated {
        return "extrapolated".into();
    }
    match d.value() {
        Some(v) => format!("delta {v:.4}"),
        None => format!("delta in [{:.4}, {:.4}]", d.lower, d.upper),
    }
}

/// How a run iterates, from its first progress report: the scheme the solver chose from the
/// settings and what the model allows, and the coarse start it made first, if any.
fn fmt_scheme(p: &Progress, operator: IterationOperator, evaluation_sweeps: usize) -> String {
    let mut line = match (p.scheme, p.extrapolate) {
        _ if operator == IterationOperator::QValues => {
            "Busoniu's fuzzy Q-iteration: full sweeps over every stored Q-value".to_string()
        }
        (Scheme::ModifiedPolicy, _) => format!(
            "modified policy iteration: full backups, each followed by up to \
             {evaluation_sweeps} evaluation sweeps under its greedy actions, every sweep \
             extrapolated"
        ),
        (_, true) => "value iteration: full backups, extrapolated every other sweep".to_string(),
        _ => "value iteration: full backups (the paper's fuzzy Q-iteration)".to_string(),
    };
    if let Some(c) = p.coarse {
        line += &format!(
            ", after a coarse start ({} on {} cores in {:.1} s)",
            count(c.sweeps, "sweep"),
            c.cores,
            c.seconds
        );
    }
    line
}

/// A progress bar on a terminal (hidden otherwise or with `--quiet`).
fn progress_bar(quiet: bool, len: u64, template: &str) -> ProgressBar {
    if quiet || !std::io::stderr().is_terminal() {
        return ProgressBar::hidden();
    }
    let b = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    b.set_style(ProgressStyle::with_template(template).expect("valid template"));
    b
}

fn stop_if(stop: &AtomicBool) -> ControlFlow<()> {
    if stop.load(Ordering::SeqCst) {
        ControlFlow::Break(())
    } else {
        ControlFlow::Continue(())
    }
}

pub(crate) fn run(args: TrainArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let config = build_config(&args)?;
    if matches!(args.learner, Learner::Fqi | Learner::LearnedModel) {
        output::check_memory(args.max_memory, &fuzzyq_sim::memory::train(&config))?;
    }
    if matches!(args.learner, Learner::Fql | Learner::Vqql) {
        for (set, flag) in solver_flags(&args) {
            refuse(
                set,
                flag,
                "sets the solver of fuzzy Q-iteration; it does not apply to --learner fql or vqql",
            )?;
        }
        return run_from_samples(&args, &config);
    }
    refuse_misplaced_flags(&args, &config)?;
    let learning = model_learning(&args, &config)?;
    let logged = match &args.transitions {
        Some(path) => {
            let task = config.build_model()?;
            let (e, d) = (
                F64Model::state_dim(&task),
                F64Model::actions(&task).dim() * F64Model::n_agents(&task),
            );
            Some(read_transitions_csv(path, e, d)?)
        }
        None => None,
    };
    plan_outputs(&args)?;
    let mut checkpoints = Checkpoints::new(
        args.checkpoint.as_deref(),
        args.checkpoint_every,
        10,
        config.to_toml(),
    )?;
    let resume = match checkpoints.resume(args.resume.as_deref(), true, "fqi")? {
        Some(RunState::Fqi(state)) => Some(state),
        _ => None,
    };
    start_pool(args.threads)?;
    let threads = rayon::current_num_threads();
    if !args.quiet {
        announce(&args, &config, threads, learning.as_ref(), logged.as_ref())?;
        if let (Some(state), Some(path)) = (&resume, &args.resume) {
            eprintln!(
                "continuing from checkpoint {} after sweep {}",
                path.display(),
                state.sweeps()
            );
        }
    }
    let device = open_device(&config, args.quiet)?;
    let task = Task {
        config: &config,
        learning: learning.as_ref(),
        logged: logged.as_ref(),
    };
    let (artifact, learned_run) = solve(&args, &task, resume, &mut checkpoints)?;
    let (device_seconds, device_beside_setup) = match device {
        Some(Opened::Before(seconds)) => (Some(seconds), Some(false)),
        Some(Opened::Beside(opening)) => {
            (Some(opening.wait().map_err(SimError::from)?), Some(true))
        }
        None => (None, None),
    };
    let written = Instant::now();
    let file = PolicyFile::Fqi(artifact);
    output::write_policy(&args.out, &file)?;
    let timings = Timings {
        device_seconds,
        device_beside_setup,
        write_seconds: written.elapsed().as_secs_f64(),
        command_seconds: started.elapsed().as_secs_f64(),
    };
    let PolicyFile::Fqi(artifact) = file else {
        unreachable!("just built")
    };
    let s = &artifact.summary;
    if !args.quiet {
        if let Some(r) = &learned_run {
            report_learned(r, args.json.is_some());
        }
        eprintln!(
            "{} after {} in {:.1} s (final delta {:.4}, xi {}); policy written to {}",
            if s.converged {
                "converged"
            } else {
                "sweep limit reached"
            },
            sweeps_done(s),
            s.seconds,
            s.final_delta,
            config.solver.xi,
            args.out.display()
        );
    }
    if let Some(path) = &args.json {
        write_json(
            path,
            &summary(&args, &task, s, (threads, timings), learned_run.as_ref()),
        )?;
    }
    Ok(())
}

/// What a fuzzy Q-iteration run solves: the configuration, and for `--learner learned-model`
/// how the model is learned and the logged transitions it is learned from, if any.
struct Task<'a> {
    config: &'a TrainConfig,
    learning: Option<&'a train::ModelLearning>,
    logged: Option<&'a fuzzyq_sim::learn::samples::Transitions>,
}

/// Refuses the flags that do not apply to this run of fuzzy Q-iteration (or of
/// `--learner learned-model`), naming each.
fn refuse_misplaced_flags(args: &TrainArgs, config: &TrainConfig) -> anyhow::Result<()> {
    let learned = args.learner == Learner::LearnedModel;
    let q_values = config.solver.operator == IterationOperator::QValues;
    if q_values {
        for (set, flag) in [
            (args.asynchronous, "--async"),
            (args.backup.is_some(), "--backup"),
            (args.extrapolate, "--extrapolate"),
            (args.evaluation_sweeps.is_some(), "--evaluation-sweeps"),
            (args.coarse_start, "--coarse-start"),
        ] {
            refuse(
                set,
                flag,
                "does not apply to --operator q-values (synchronous sweeps over every stored Q-value)",
            )?;
        }
    }
    for (set, flag) in [
        (args.samples.is_some(), "--samples"),
        (args.transitions.is_some(), "--transitions"),
        (args.rounds.is_some(), "--rounds"),
        (args.epsilon.is_some(), "--epsilon"),
    ] {
        refuse(
            set && !learned,
            flag,
            "applies to --learner learned-model only",
        )?;
    }
    for (set, flag) in [
        (args.episodes.is_some(), "--episodes"),
        (args.literal, "--literal"),
        (args.cells.is_some(), "--cells"),
        (args.curve.is_some(), "--curve"),
        (args.plot.is_some(), "--plot"),
    ] {
        refuse(set, flag, "applies to --learner fql or vqql only")?;
    }
    for (set, flag) in [
        (args.checkpoint.is_some(), "--checkpoint"),
        (args.resume.is_some(), "--resume"),
    ] {
        refuse(
            set && learned,
            flag,
            "applies to --learner fqi, fql and vqql (a learned model's run is not resumable)",
        )?;
        refuse(
            set && q_values,
            flag,
            "needs --operator values (runs of the q-values operator cannot be continued)",
        )?;
    }
    Ok(())
}

/// `--learner learned-model`: how the model is learned (checked against the task); `None`
/// for fuzzy Q-iteration on the task's own model.
fn model_learning(
    args: &TrainArgs,
    config: &TrainConfig,
) -> anyhow::Result<Option<train::ModelLearning>> {
    if args.learner != Learner::LearnedModel {
        return Ok(None);
    }
    let mut l = train::ModelLearning::new(args.samples.unwrap_or(20_000), args.seed);
    l.rounds = args.rounds.unwrap_or(l.rounds);
    l.epsilon = args.epsilon.unwrap_or(l.epsilon);
    l.validate()?;
    train::check_learnable(config)?;
    Ok(Some(l))
}

/// The GPU of a `--device gpu` run: opened before the run, or being opened beside its set-up.
enum Opened {
    /// Opened first, in this many seconds.
    Before(f64),
    /// Being opened on a thread of its own while the run is set up on the host.
    Beside(fuzzyq_gpu::Opening),
}

/// Host estimates below which a run opens the GPU beside its set-up ([`open_device`]).
const BESIDE_SETUP_BELOW: f64 = (1u64 << 30) as f64;

/// Opens the GPU of a `--device gpu` run, once for the run (the solver shares it), and says
/// which (unless `quiet`). A run whose host estimate is under 1 GiB opens it on a thread of
/// its own while the host computes its rewards and tables (the solver's open waits for it):
/// the driver's start-up is then hidden behind that set-up. A larger run opens it first, so
/// that a machine without a GPU says so before a set-up of seconds or minutes, and so does
/// every run under `FUZZYQ_GPU_OPEN=first` (for timing the two).
fn open_device(config: &TrainConfig, quiet: bool) -> anyhow::Result<Option<Opened>> {
    if config.solver.device != Device::Gpu {
        return Ok(None);
    }
    let show = move |gpu: &fuzzyq_gpu::Gpu| {
        let a = gpu.summary();
        if !quiet {
            eprintln!(
                "GPU: {} ({}, {}; {}; fma {})",
                a.name,
                a.backend,
                a.driver,
                super::bench::gpu_memory(a.memory),
                if a.fused_fma {
                    "fused: the CPU's bits"
                } else {
                    "not fused: each product rounded first, so the last bits differ from the \
                     CPU's"
                }
            );
        }
    };
    let opening = fuzzyq_gpu::Gpu::open_shared_in_background(show);
    let first = std::env::var("FUZZYQ_GPU_OPEN").is_ok_and(|v| v == "first");
    if !first && fuzzyq_sim::memory::train(config).bytes < BESIDE_SETUP_BELOW {
        return Ok(Some(Opened::Beside(opening)));
    }
    let seconds = opening.wait().map_err(SimError::from)?;
    Ok(Some(Opened::Before(seconds)))
}

/// The run's opening lines on stderr: the problem and where a learned model's data come from
/// (the GPU's line comes when it is open: [`open_device`]).
fn announce(
    args: &TrainArgs,
    config: &TrainConfig,
    threads: usize,
    learning: Option<&train::ModelLearning>,
    logged: Option<&fuzzyq_sim::learn::samples::Transitions>,
) -> anyhow::Result<()> {
    let n_cores = config.n_cores();
    let joint = config.n_joint_actions();
    eprintln!(
        "fuzzyq train: {}, {n_cores} cores x {joint} joint actions ({:.3e} Q-values), \
         gamma {}, xi {}, {} sweeps, {threads} threads",
        config.env.name(),
        n_cores as f64 * joint as f64,
        config.solver.gamma,
        config.solver.xi,
        if config.solver.sweep == SweepMode::Synchronous {
            "synchronous"
        } else {
            "asynchronous"
        },
    );
    match (learning, logged) {
        (_, Some(data)) => eprintln!(
            "learned model: {} logged transitions from {}, fitted per dynamics block, then solved",
            data.len(),
            args.transitions
                .as_deref()
                .unwrap_or(Path::new(""))
                .display()
        ),
        (Some(l), None) => eprintln!(
            "learned model: {} transitions from the plant (random actions, episodes of {} \
             steps, seed {}), fitted per dynamics block, then solved{}",
            l.collection.samples,
            l.collection.episode_steps,
            l.collection.seed,
            if l.rounds > 1 {
                format!(
                    "; then {} more round{} of {} transitions, epsilon-greedy (epsilon {}) \
                     with the policy so far, refitted and solved",
                    l.rounds - 1,
                    if l.rounds == 2 { "" } else { "s" },
                    l.collection.samples,
                    l.epsilon
                )
            } else {
                String::new()
            }
        ),
        _ => {}
    }
    Ok(())
}

/// Solves the task with a progress bar (or plain lines when stderr is not a terminal),
/// writing checkpoints as asked; Ctrl-C stops after the current sweep with a checkpoint.
fn solve(
    args: &TrainArgs,
    task: &Task<'_>,
    resume: Option<FqiState<'static>>,
    checkpoints: &mut Checkpoints,
) -> anyhow::Result<(PolicyArtifact, Option<train::LearnedModelRun>)> {
    let config = task.config;
    let stop = output::interrupt_flag();
    let bar = progress_bar(
        args.quiet,
        0,
        "{spinner} sweep {pos}/{len} (a-priori bound) {msg} [{elapsed_precise}]",
    );
    bar.set_message("preparing");
    bar.enable_steady_tick(Duration::from_millis(200));
    let plain = !args.quiet && !std::io::stderr().is_terminal();
    let evaluation_sweeps = config.solver.evaluation_sweeps;
    let mut scheme_shown = args.quiet;
    let mut observer = |p: &fuzzyq_core::solver::Progress, state: Option<&FqiState<'_>>| {
        if !std::mem::replace(&mut scheme_shown, true) {
            // What the solver decided to run, known from its first report.
            let line = fmt_scheme(p, config.solver.operator, evaluation_sweeps);
            if plain {
                eprintln!("{line}");
            } else {
                bar.println(line);
            }
        }
        bar.set_length(p.bound as u64);
        bar.set_position(p.record.sweep as u64);
        bar.set_message(fmt_delta(p));
        if plain && (p.record.sweep == 1 || p.record.sweep.is_multiple_of(10)) {
            eprintln!(
                "sweep {}/{} (a-priori bound): {}, {:.1} s",
                p.record.sweep,
                p.bound,
                fmt_delta(p),
                p.record.seconds
            );
        }
        let interrupted = stop_if(&stop).is_break();
        checkpoints.after(p.record.sweep, interrupted, || {
            state.map(|s| RunState::Fqi(s.borrowed()))
        })
    };
    let with_run = |r: train::LearnedModelRun| (r.artifact.clone(), Some(r));
    let result = match (task.learning, task.logged) {
        (Some(l), None) => train::train_learned(config, l, |p| observer(p, None)).map(with_run),
        (Some(l), Some(data)) => {
            train::train_on_transitions(config, data, &l.fit, |p| observer(p, None)).map(with_run)
        }
        (None, _) => train::train_showing(config, resume, args.checkpoint.is_some(), observer)
            .map(|a| (a, None)),
    };
    bar.finish_and_clear();
    if let Some(e) = checkpoints.failure() {
        return Err(e);
    }
    match result {
        Ok(a) => Ok(a),
        Err(SimError::Solve(SolveError::Interrupted { sweeps })) => {
            Err(Failure::Interrupted(checkpoints.interrupted(&format!("{sweeps} sweeps"))).into())
        }
        Err(e) => Err(e.into()),
    }
}

/// What a learned model's run collected and fitted, on stderr.
fn report_learned(r: &train::LearnedModelRun, listed_in_json: bool) {
    let rows: usize = r.fit.blocks.iter().map(|b| b.rows).sum();
    let (max_l1, mean_l1) = r.table_error.iter().fold((0.0f64, 0.0), |(m, a), t| {
        (m.max(t.max_l1), a + t.mean_l1 / r.table_error.len() as f64)
    });
    eprintln!(
        "learned model: {} transitions collected and fitted in {:.2} s; {} of {rows} rows \
         needed a wider kernel than their core's{}; L1 distance of the rows to the true \
         noise-free model's: max {max_l1:.3}, mean {mean_l1:.4}",
        r.fit.samples,
        r.learning_seconds,
        r.fit.under_sampled_rows(),
        if listed_in_json {
            " (listed in the JSON)"
        } else {
            ""
        },
    );
    if r.rounds.len() > 1 {
        for (k, round) in r.rounds.iter().enumerate() {
            eprintln!(
                "round {}: {} transitions, {} rows widened, {} sweeps, {:.1} s",
                k + 1,
                round.transitions,
                round.under_sampled_rows,
                round.sweeps,
                round.seconds
            );
        }
    }
    if r.fit.reward_mismatches > 0 {
        eprintln!(
            "warning: {} transitions recorded a reward other than the task's",
            r.fit.reward_mismatches
        );
    }
}

/// The `--json` summary of a run of fuzzy Q-iteration.
fn summary<'a>(
    args: &'a TrainArgs,
    task: &Task<'_>,
    s: &'a TrainSummary,
    (threads, timings): (usize, Timings),
    learned_run: Option<&'a train::LearnedModelRun>,
) -> Summary<'a> {
    let config = task.config;
    let (n_cores, joint) = (config.n_cores(), config.n_joint_actions());
    let gamma = config.solver.gamma;
    Summary {
        env: config.env.name(),
        policy: args.out.display().to_string(),
        sweeps: s.sweeps,
        full_backups: s.sweeps - s.evaluation.len(),
        evaluation_sweeps: s.evaluation.len(),
        converged: s.converged,
        delta_inf: s.final_delta,
        xi: config.solver.xi,
        gamma,
        error_bound: gamma / (1.0 - gamma) * s.final_delta,
        sweep_bound: s.sweep_bound,
        seconds: s.seconds,
        seconds_per_sweep: s.seconds / s.sweeps.max(1) as f64,
        cores: n_cores,
        joint_actions: joint,
        q_values: n_cores as f64 * joint as f64,
        backup: &s.backup,
        kernel: &s.kernel,
        multiply_adds_per_sweep: s.multiply_adds_per_sweep,
        sweep_seconds: s.sweep_seconds,
        evaluation_seconds: s.evaluation_seconds,
        setup_seconds: s.setup_seconds,
        result_seconds: s.result_seconds,
        timings,
        // Billions of multiply-adds per second over the full backups.
        gflops_fma: s.multiply_adds_per_sweep.map(|m| {
            m * (s.sweeps - s.evaluation.len()) as f64
                / (s.sweep_seconds - s.evaluation_seconds).max(1e-9)
                / 1e9
        }),
        precision: config.solver.precision,
        sweep: config.solver.sweep,
        absorbing_goal: config.solver.absorbing_goal,
        threads,
        peak_memory_mb: peak_memory_mb(),
        deltas: &s.deltas,
        extrapolated: &s.extrapolated,
        coarse_start: s.coarse.as_deref().map(|c| CoarseSummary {
            cores: c.cores,
            sweeps: c.sweeps,
            seconds: c.seconds,
        }),
        learned_model: learned_run.map(|r| LearnedSummary {
            source: args
                .transitions
                .as_ref()
                .map_or_else(|| "plant".into(), |p| p.display().to_string()),
            samples: r.fit.samples,
            seed: args.transitions.is_none().then_some(args.seed),
            learning_seconds: r.learning_seconds,
            fit: &r.fit,
            table_error: &r.table_error,
            rounds: &r.rounds,
            epsilon: task.learning.filter(|l| l.rounds > 1).map(|l| l.epsilon),
        }),
    }
}

/// The flags of the fuzzy Q-iteration solver, and whether each was given.
fn solver_flags(args: &TrainArgs) -> [(bool, &'static str); 14] {
    [
        (args.xi.is_some(), "--xi"),
        (args.max_sweeps.is_some(), "--max-sweeps"),
        (args.operator.is_some(), "--operator"),
        (args.asynchronous, "--async"),
        (args.absorbing_goal, "--absorbing-goal"),
        (args.extrapolate, "--extrapolate"),
        (args.no_extrapolate, "--no-extrapolate"),
        (args.evaluation_sweeps.is_some(), "--evaluation-sweeps"),
        (args.coarse_start, "--coarse-start"),
        (args.no_coarse_start, "--no-coarse-start"),
        (args.backup.is_some(), "--backup"),
        (args.precision.is_some(), "--precision"),
        (args.kernel.is_some(), "--kernel"),
        (args.device.is_some(), "--device"),
    ]
}

/// Plans the outputs of `train` against its input files ([`output::plan`]).
fn plan_outputs(args: &TrainArgs) -> anyhow::Result<()> {
    // A run usually continues into the checkpoint it resumes from: then that file is the
    // checkpoint output only (it is read whole before the first write).
    let same = |a: &Path, b: &Path| {
        a == b
            || std::fs::canonicalize(a)
                .ok()
                .zip(std::fs::canonicalize(b).ok())
                .is_some_and(|(x, y)| x == y)
    };
    let resume = args
        .resume
        .as_deref()
        .filter(|r| !args.checkpoint.as_deref().is_some_and(|c| same(c, r)));
    output::plan(
        &[
            (Some(&args.out), "--out"),
            (args.json.as_deref(), "--json"),
            (args.curve.as_deref(), "--curve"),
            (args.plot.as_deref(), "--plot"),
            (args.checkpoint.as_deref(), "--checkpoint"),
        ],
        &[
            (args.task.config.as_deref(), "--config"),
            (args.arena.as_deref(), "--arena"),
            (args.transitions.as_deref(), "--transitions"),
            (resume, "--resume"),
        ],
    )
}

/// `fuzzyq train --learner fql|vqql`: learning from samples with the additive layout.
fn run_from_samples(args: &TrainArgs, config: &TrainConfig) -> anyhow::Result<()> {
    let learning = sample_learning(args, config)?;
    plan_outputs(args)?;
    if let Some(p) = &args.plot {
        plot::check_extension(p, "--plot")?;
    }
    let fql = learning.fql.clone();
    let mut checkpoints = Checkpoints::new(
        args.checkpoint.as_deref(),
        args.checkpoint_every,
        100,
        format!("{}\n# learning\n{learning:#?}\n", config.to_toml()),
    )?;
    let resume = match checkpoints.resume(args.resume.as_deref(), false, args.learner.name())? {
        Some(RunState::Fql(state)) => Some(state),
        _ => None,
    };
    let stop = output::interrupt_flag();
    let bar = progress_bar(
        args.quiet,
        fql.episodes as u64,
        "{spinner} episode {pos}/{len} {msg} [{elapsed_precise}]",
    );
    let env = config.env.name();
    let what = match args.learner {
        Learner::Vqql => "VQQL (k-means cells, tabular Q-learning)",
        _ => "model-free fuzzy Q-learning",
    };
    if !args.quiet {
        eprintln!(
            "fuzzyq train: {env}, {what} ({:?} update, additive layout), {} episodes of at most \
             {} steps, seed {}",
            fql.update, fql.episodes, fql.max_steps, fql.seed
        );
        if let Some(v) = &learning.vqql {
            eprintln!(
                "building the codebooks: k-means with {} cells per agent on {} explored states",
                v.cells, v.samples
            );
        }
    }
    let plain = !args.quiet && !std::io::stderr().is_terminal();
    let started = std::time::Instant::now();
    if let (Some(state), false, Some(path)) = (&resume, args.quiet, &args.resume) {
        eprintln!(
            "continuing from checkpoint {} after episode {}",
            path.display(),
            state.episodes()
        );
    }
    let progress = |r: &EpisodeRecord| {
        bar.set_position(r.episode as u64 + 1);
        if let Some(s) = r.eval_success_rate {
            bar.set_message(format!("greedy success {:.0}%", 100.0 * s));
            if plain {
                eprintln!(
                    "episode {}: greedy evaluation success {:.0}%",
                    r.episode + 1,
                    100.0 * s
                );
            }
        }
    };
    let observer = Episodes {
        progress,
        checkpoints: &mut checkpoints,
        resume,
        stop: &stop,
    };
    let learned = train::learn_from_samples(config, &learning, observer);
    bar.finish_and_clear();
    if let Some(e) = checkpoints.failure() {
        return Err(e);
    }
    let learned = learned?;
    let outcome = &learned.outcome;
    if stop.load(Ordering::SeqCst) {
        let done = format!("{} episodes", outcome.curve.len());
        return Err(Failure::Interrupted(checkpoints.interrupted(&done)).into());
    }
    let seconds = started.elapsed().as_secs_f64();
    output::write_policy(&args.out, &learned.file)?;
    sample_outputs(args, config, &fql, outcome, seconds)
}

/// `--learner fql` or `vqql`: the learner's settings from the environment's defaults and the
/// flags, checked.
fn sample_learning(args: &TrainArgs, config: &TrainConfig) -> anyhow::Result<SampleLearning> {
    // Which learners apply to the environment first, then which flags apply to the learner.
    SampleLearning::defaults(config, args.learner)?;
    refuse(
        args.cells.is_some() && args.learner != Learner::Vqql,
        "--cells",
        "applies to --learner vqql only",
    )?;
    let options = SampleOptions {
        episodes: args.episodes,
        literal: args.literal,
        cells: args.cells,
        seed: args.seed,
    };
    Ok(SampleLearning::with_options(
        config,
        args.learner,
        &options,
    )?)
}

/// A learner from samples' outputs besides the policy file: the learning curve (CSV and
/// figure), the `--json` summary and the closing line.
fn sample_outputs(
    args: &TrainArgs,
    config: &TrainConfig,
    fql: &fuzzyq_sim::learn::fql::FqlConfig,
    outcome: &fuzzyq_sim::learn::fql::FqlOutcome,
    seconds: f64,
) -> anyhow::Result<()> {
    let env = config.env.name();
    if let Some(p) = &args.curve {
        let mut text = Vec::new();
        fuzzyq_sim::learn::fql::write_curve_csv(&outcome.curve, &mut text)?;
        output::write_file(p, &text)?;
    }
    if let Some(p) = &args.plot {
        let title = match &config.env {
            EnvConfig::Pointmass(pm) => format!(
                "{} on {} point masses (seed {})",
                if args.learner == Learner::Vqql {
                    "VQQL"
                } else {
                    "Fuzzy Q-learning"
                },
                pm.agents,
                fql.seed
            ),
            _ => format!("Fuzzy Q-learning on two Khepera robots (seed {})", fql.seed),
        };
        plot::learning_curve_figure(p, &outcome.curve, &title)?;
    }
    let last_eval = outcome.curve.iter().rev().find_map(|r| r.eval_success_rate);
    let rewarded = outcome.curve.iter().filter(|r| r.ret > 0.0).count();
    if let Some(j) = &args.json {
        write_json(
            j,
            &SampleSummary {
                env,
                learner: args.learner.name(),
                update: fql.update,
                policy: args.out.display().to_string(),
                episodes: outcome.curve.len(),
                steps_total: outcome.steps_total,
                rewarded_episodes: rewarded,
                converged_at: outcome.converged_at,
                final_eval_success_rate: last_eval,
                seconds,
                seed: fql.seed,
            },
        )?;
    }
    if !args.quiet {
        eprintln!(
            "learned in {seconds:.1} s: {} episodes, {} steps ({rewarded} with a positive return), \
             converged {}, last greedy evaluation success {}; wrote {}",
            outcome.curve.len(),
            outcome.steps_total,
            outcome
                .converged_at
                .map_or_else(|| "no".to_string(), |e| format!("at episode {e}")),
            last_eval.map_or_else(|| "n/a".to_string(), |s| format!("{:.0}%", 100.0 * s)),
            args.out.display()
        );
    }
    Ok(())
}
