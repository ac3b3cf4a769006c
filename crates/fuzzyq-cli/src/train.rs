//! `fuzzyq train`.

use std::io::IsTerminal;
use std::ops::ControlFlow;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use clap::{Args, ValueEnum};
use fuzzyq_core::solver::{Progress, SolveError};
use fuzzyq_sim::config::{Backup, EnvConfig, KernelChoice, Precision, Sweep, TrainConfig};
use fuzzyq_sim::{PolicyArtifact, SimError};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;

use crate::{Env, Failure, check_writable, write_json};

#[derive(Args, Debug)]
pub(crate) struct TrainArgs {
    /// The environment.
    #[arg(long, value_enum, default_value_t = Env::Pointmass)]
    env: Env,
    /// A TOML configuration (see `fuzzyq config`); flags below override its values.
    #[arg(long, value_name = "FILE.toml")]
    config: Option<PathBuf>,
    /// Discount factor in [0, 1).
    #[arg(long, value_name = "G")]
    gamma: Option<f64>,
    /// Stop when the sweep's change ||theta_{k+1} - theta_k||_inf is at most X.
    #[arg(long, value_name = "X")]
    xi: Option<f64>,
    /// Sweep limit.
    #[arg(long, value_name = "K")]
    max_sweeps: Option<usize>,
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
    /// Backup implementation.
    #[arg(long, value_enum)]
    backup: Option<BackupArg>,
    /// Solver precision.
    #[arg(long, value_enum)]
    precision: Option<PrecisionArg>,
    /// Kernel instance of the block backup (default: the fastest this CPU runs; all give
    /// identical results).
    #[arg(long, value_enum)]
    kernel: Option<KernelArg>,
    /// Worker threads (default: one per core; results do not depend on it).
    #[arg(long, value_name = "N")]
    threads: Option<usize>,
    /// Where to write the policy file.
    #[arg(long, value_name = "POLICY")]
    out: PathBuf,
    /// Also write a JSON summary of the run.
    #[arg(long, value_name = "SUMMARY.json")]
    json: Option<PathBuf>,
    /// No progress output.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum BackupArg {
    Auto,
    Block,
    Generic,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum KernelArg {
    Scalar,
    Avx2,
    Avx512,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum PrecisionArg {
    F32,
    F64,
}

/// The `--json` summary.
#[derive(Serialize)]
struct Summary<'a> {
    env: &'a str,
    policy: String,
    sweeps: usize,
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
    gflops_fma: Option<f64>,
    precision: Precision,
    sweep: Sweep,
    absorbing_goal: bool,
    threads: usize,
    peak_memory_mb: Option<f64>,
    deltas: &'a [(f64, f64)],
    extrapolated: &'a [usize],
}

fn build_config(args: &TrainArgs) -> anyhow::Result<TrainConfig> {
    let mut config = match &args.config {
        Some(path) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read config {}", path.display()))?;
            TrainConfig::from_toml(&text).with_context(|| format!("config {}", path.display()))?
        }
        None => TrainConfig::default(),
    };
    if config.env.name() != args.env.name() {
        anyhow::bail!(
            "the config describes env \"{}\" but --env is {}",
            config.env.name(),
            args.env.name()
        );
    }
    let s = &mut config.solver;
    if let Some(g) = args.gamma {
        s.gamma = g;
    }
    if let Some(x) = args.xi {
        s.xi = x;
    }
    if let Some(k) = args.max_sweeps {
        s.max_sweeps = k;
    }
    if args.asynchronous {
        s.sweep = Sweep::Async;
    }
    if args.absorbing_goal {
        s.absorbing_goal = true;
    }
    if args.extrapolate {
        s.extrapolate = true;
    }
    if args.no_extrapolate {
        s.extrapolate = false;
    }
    if let Some(b) = args.backup {
        s.backup = match b {
            BackupArg::Auto => Backup::Auto,
            BackupArg::Block => Backup::Block,
            BackupArg::Generic => Backup::Generic,
        };
    }
    if let Some(k) = args.kernel {
        s.kernel = Some(match k {
            KernelArg::Scalar => KernelChoice::Scalar,
            KernelArg::Avx2 => KernelChoice::Avx2,
            KernelArg::Avx512 => KernelChoice::Avx512,
        });
    }
    if let Some(p) = args.precision {
        s.precision = match p {
            PrecisionArg::F32 => Precision::F32,
            PrecisionArg::F64 => Precision::F64,
        };
    }
    config.validate()?;
    Ok(config)
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
    if p.record.extrapolated {
        return "extrapolated".into();
    }
    match d.value() {
        Some(v) => format!("delta {v:.4}"),
        None => format!("delta in [{:.4}, {:.4}]", d.lower, d.upper),
    }
}

pub(crate) fn run(args: TrainArgs) -> anyhow::Result<()> {
    let config = build_config(&args)?;
    check_writable(&args.out, "policy")?;
    if let Some(j) = &args.json {
        check_writable(j, "summary")?;
    }
    if let Some(n) = args.threads {
        if n == 0 {
            anyhow::bail!("--threads must be at least 1");
        }
        rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build_global()
            .context("cannot start the thread pool")?;
    }
    let threads = rayon::current_num_threads();

    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        // A second Ctrl-C while the first is being honoured kills the process as usual.
        let _ = ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
        });
    }

    let n_cores = config.n_cores();
    let env = config.env.name();
    let joint = match &config.env {
        EnvConfig::Pointmass(p) => p.force_levels.len().pow(2 * p.agents as u32),
    };
    let tty = std::io::stderr().is_terminal();
    if !args.quiet {
        eprintln!(
            "fuzzyq train: {env}, {n_cores} cores x {joint} joint actions ({:.3e} Q-values), \
             gamma {}, xi {}, {} sweeps{}, {threads} threads",
            n_cores as f64 * joint as f64,
            config.solver.gamma,
            config.solver.xi,
            match config.solver.sweep {
                Sweep::Sync => "synchronous",
                Sweep::Async => "asynchronous",
            },
            if config.solver.extrapolate && config.solver.sweep == Sweep::Sync {
                " with extrapolation"
            } else {
                ""
            },
        );
    }
    let bar = if args.quiet || !tty {
        ProgressBar::hidden()
    } else {
        let b = ProgressBar::with_draw_target(Some(0), ProgressDrawTarget::stderr());
        b.set_style(
            ProgressStyle::with_template(
                "{spinner} sweep {pos}/{len} (a-priori bound) {msg} [{elapsed_precise}]",
            )
            .expect("valid template"),
        );
        b.set_message("preparing");
        b.enable_steady_tick(Duration::from_millis(200));
        b
    };
    let plain = !args.quiet && !tty;
    let result = fuzzyq_sim::train::train(&config, |p| {
        bar.set_length(p.bound as u64);
        bar.set_position(p.record.sweep as u64);
        bar.set_message(fmt_delta(p));
        if plain && (p.record.sweep == 1 || p.record.sweep % 10 == 0) {
            eprintln!(
                "sweep {}/{} (a-priori bound): {}, {:.1} s",
                p.record.sweep,
                p.bound,
                fmt_delta(p),
                p.record.seconds
            );
        }
        if stop.load(Ordering::SeqCst) {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    });
    bar.finish_and_clear();
    let artifact: PolicyArtifact = match result {
        Ok(a) => a,
        Err(SimError::Solve(SolveError::Interrupted { sweeps })) => {
            return Err(Failure::Interrupted(format!(
                "interrupted after {sweeps} sweeps; no policy was written"
            ))
            .into());
        }
        Err(e) => return Err(e.into()),
    };
    artifact.save(&args.out).context("cannot save the policy")?;
    let s = &artifact.summary;
    if !args.quiet {
        eprintln!(
            "{} after {} sweeps in {:.1} s (final delta {:.4}, xi {}); policy written to {}",
            if s.converged {
                "converged"
            } else {
                "sweep limit reached"
            },
            s.sweeps,
            s.seconds,
            s.final_delta,
            config.solver.xi,
            args.out.display()
        );
    }
    if let Some(path) = &args.json {
        let gamma = config.solver.gamma;
        let summary = Summary {
            env,
            policy: args.out.display().to_string(),
            sweeps: s.sweeps,
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
            // Billions of multiply-adds per second over the sweeps.
            gflops_fma: s
                .multiply_adds_per_sweep
                .map(|m| m * s.sweeps as f64 / s.sweep_seconds.max(1e-9) / 1e9),
            precision: config.solver.precision,
            sweep: config.solver.sweep,
            absorbing_goal: config.solver.absorbing_goal,
            threads,
            peak_memory_mb: peak_memory_mb(),
            deltas: &s.deltas,
            extrapolated: &s.extrapolated,
        };
        write_json(path, &summary)?;
    }
    Ok(())
}
