//! `fuzzyq train`.

use std::io::IsTerminal;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::Context;
use clap::{Args, ValueEnum};
use fuzzyq_core::solver::{Progress, SolveError};
use fuzzyq_sim::io::config::{Backup, EnvConfig, KernelChoice, Precision, Sweep, TrainConfig};
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
    /// dcmotor, pendulum: the named grid, actions, gamma and xi (`toolbox-demo`: the
    /// toolbox demo's coarse grid; `fine`: the toolbox's default fine grid) [default: fine].
    #[arg(long, value_name = "NAME")]
    preset: Option<String>,
    /// Discount factor in [0, 1).
    #[arg(long, value_name = "G")]
    gamma: Option<f64>,
    /// Stop when the sweep's change ||theta_{k+1} - theta_k||_inf is at most X.
    #[arg(long, value_name = "X")]
    xi: Option<f64>,
    /// Sweep limit.
    #[arg(long, value_name = "K")]
    max_sweeps: Option<usize>,
    /// The iteration: `values` (default; only V is stored, any grid size) or `q-values`
    /// (Busoniu's fuzzy Q-iteration as the ApproxRL toolbox runs it, theta stored).
    #[arg(long, value_enum)]
    operator: Option<OperatorArg>,
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
    /// The arena of the khepera environment (TOML with walls and obstacles); replaces the
    /// config's `[env.arena]`.
    #[arg(long, value_name = "FILE.toml")]
    arena: Option<PathBuf>,
    /// The learner: joint fuzzy Q-iteration on the model (`fqi`); model-free fuzzy
    /// Q-learning with the additive layout (`fql`: on the point masses' own states, or on the
    /// robots' quantised observations); VQQL (`vqql`, point masses: k-means cells per agent
    /// and tabular Q-learning). `fql` and `vqql` write a TOML policy of the learned
    /// parameters.
    #[arg(long, value_enum, default_value_t = LearnerArg::Fqi)]
    learner: LearnerArg,
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
    /// fql, vqql: seed of exploration and starts.
    #[arg(long, value_name = "S", default_value_t = 0)]
    seed: u64,
    /// fql: write the learning curve (one row per episode) as CSV.
    #[arg(long, value_name = "FILE.csv")]
    curve: Option<PathBuf>,
    /// fql: draw the learning curve (PNG or SVG).
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    plot: Option<PathBuf>,
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

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum LearnerArg {
    /// Joint fuzzy Q-iteration.
    Fqi,
    /// Model-free fuzzy Q-learning (additive layout).
    Fql,
    /// VQQL: k-means cells and tabular Q-learning (point masses).
    Vqql,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum OperatorArg {
    Values,
    QValues,
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

/// The configuration file `path` (or the defaults of `env`, or its named preset), which must
/// describe `env`.
pub(crate) fn load_config(
    path: Option<&Path>,
    env: Env,
    preset: Option<&str>,
) -> anyhow::Result<TrainConfig> {
    let config = match (path, preset) {
        (Some(_), Some(_)) => anyhow::bail!("give either --config or --preset, not both"),
        (Some(path), None) => {
            let text = std::fs::read_to_string(path)
                .with_context(|| format!("cannot read config {}", path.display()))?;
            TrainConfig::from_toml(&text).with_context(|| format!("config {}", path.display()))?
        }
        (None, Some(p)) => TrainConfig::from_preset(env.name(), p)?,
        (None, None) => TrainConfig::default_for(env.name())?,
    };
    if config.env.name() != env.name() {
        anyhow::bail!(
            "the config describes env \"{}\" but --env is {}",
            config.env.name(),
            env.name()
        );
    }
    Ok(config)
}

fn build_config(args: &TrainArgs) -> anyhow::Result<TrainConfig> {
    let mut config = load_config(args.config.as_deref(), args.env, args.preset.as_deref())?;
    if let Some(path) = &args.arena {
        match &mut config.env {
            EnvConfig::Khepera(k) => k.arena = fuzzyq_sim::model::arena::Arena::from_file(path)?,
            _ => anyhow::bail!("--arena applies to --env khepera only"),
        }
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
    if let Some(o) = args.operator {
        s.operator = match o {
            OperatorArg::Values => fuzzyq_sim::io::config::IterationOperator::Values,
            OperatorArg::QValues => fuzzyq_sim::io::config::IterationOperator::QValues,
        };
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
    if args.learner != LearnerArg::Fqi {
        return run_fql(&args, &config);
    }
    for (set, flag) in [
        (args.episodes.is_some(), "--episodes"),
        (args.literal, "--literal"),
        (args.cells.is_some(), "--cells"),
        (args.curve.is_some(), "--curve"),
        (args.plot.is_some(), "--plot"),
    ] {
        if set {
            anyhow::bail!("{flag} applies to --learner fql or vqql only");
        }
    }
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
        EnvConfig::Khepera(k) => fuzzyq_sim::model::khepera::N_ACTIONS.pow(k.agents as u32),
        EnvConfig::Dcmotor(c) => c.actions.len(),
        EnvConfig::Pendulum(c) => c.actions.len(),
        EnvConfig::Carhill(c) => c.actions.len(),
        EnvConfig::Arm(c) => c.actions.len().pow(2),
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

/// A model-free learner's run: what it trains on, and how its policy file is written.
enum SampleLearner<'a> {
    Khepera(&'a fuzzyq_sim::model::khepera::KheperaConfig),
    PointMass {
        model: Box<fuzzyq_sim::PointMass>,
        features: Option<fuzzyq_sim::learn::fql::FeatureSpace>,
        vqql: Option<fuzzyq_sim::learn::vqql::VqqlConfig>,
    },
}

/// `fuzzyq train --learner fql|vqql`: model-free learning with the additive layout.
fn run_fql(args: &TrainArgs, config: &TrainConfig) -> anyhow::Result<()> {
    use fuzzyq_sim::learn::tasks::pointmass::{self as pointmass_fql, PointMassPolicyFile};
    use fuzzyq_sim::learn::vqql::{self, VqqlConfig};
    let (learner, mut fql) = match (&config.env, args.learner) {
        (EnvConfig::Khepera(k), LearnerArg::Fql) => (
            SampleLearner::Khepera(k),
            fuzzyq_sim::learn::tasks::khepera::default_fql_config(),
        ),
        (EnvConfig::Khepera(_), _) => {
            anyhow::bail!("--learner vqql is available for --env pointmass only")
        }
        (
            EnvConfig::Dcmotor(_)
            | EnvConfig::Pendulum(_)
            | EnvConfig::Carhill(_)
            | EnvConfig::Arm(_),
            _,
        ) => {
            anyhow::bail!(
                "--learner fql and vqql are available for --env pointmass and khepera only"
            )
        }
        (EnvConfig::Pointmass(p), learner) => {
            let model = Box::new(fuzzyq_sim::PointMass::new(p.clone())?);
            let g = &config.grid;
            let (features, vqql) = if learner == LearnerArg::Vqql {
                let cells = g.position_cores.len().pow(2) * g.velocity_cores.len().pow(2);
                let v = VqqlConfig {
                    cells: args.cells.unwrap_or(cells),
                    seed: args.seed,
                    ..VqqlConfig::default()
                };
                v.validate()?;
                (None, Some(v))
            } else {
                let f = pointmass_fql::feature_space(&model, &g.position_cores, &g.velocity_cores)?;
                (Some(f), None)
            };
            (
                SampleLearner::PointMass {
                    model,
                    features,
                    vqql,
                },
                pointmass_fql::default_fql_config(),
            )
        }
    };
    if args.cells.is_some() && args.learner != LearnerArg::Vqql {
        anyhow::bail!("--cells applies to --learner vqql only");
    }
    check_writable(&args.out, "policy")?;
    for (p, what) in [
        (&args.curve, "curve"),
        (&args.plot, "plot"),
        (&args.json, "summary"),
    ] {
        if let Some(p) = p {
            check_writable(p, what)?;
        }
    }
    if let Some(p) = &args.plot {
        crate::plot::check_extension(p)?;
    }
    fql.seed = args.seed;
    fql.gamma = config.solver.gamma;
    if let Some(n) = args.episodes {
        fql.episodes = n;
    }
    if args.literal {
        fql.update = fuzzyq_sim::learn::fql::Update::Literal;
    }
    fql.validate()?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        let _ = ctrlc::set_handler(move || {
            if stop.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
        });
    }
    let tty = std::io::stderr().is_terminal();
    let bar = if args.quiet || !tty {
        ProgressBar::hidden()
    } else {
        let b =
            ProgressBar::with_draw_target(Some(fql.episodes as u64), ProgressDrawTarget::stderr());
        b.set_style(
            ProgressStyle::with_template("{spinner} episode {pos}/{len} {msg} [{elapsed_precise}]")
                .expect("valid template"),
        );
        b
    };
    let (env, what) = match (&learner, args.learner) {
        (SampleLearner::Khepera(_), _) => ("khepera", "model-free fuzzy Q-learning"),
        (_, LearnerArg::Vqql) => ("pointmass", "VQQL (k-means cells, tabular Q-learning)"),
        _ => ("pointmass", "model-free fuzzy Q-learning"),
    };
    if !args.quiet {
        eprintln!(
            "fuzzyq train: {env}, {what} ({:?} update, additive layout), {} episodes of at most \
             {} steps, seed {}",
            fql.update, fql.episodes, fql.max_steps, fql.seed
        );
    }
    let plain = !args.quiet && !tty;
    let started = std::time::Instant::now();
    let progress = |r: &fuzzyq_sim::learn::fql::EpisodeRecord| {
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
        if stop.load(Ordering::SeqCst) {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    };
    let starts = pointmass_fql::default_starts();
    let outcome = match &learner {
        SampleLearner::Khepera(k) => {
            fuzzyq_sim::learn::tasks::khepera::train_fql(k, &fql, progress)?
        }
        SampleLearner::PointMass {
            model,
            features: Some(f),
            ..
        } => pointmass_fql::train_fql(model, f, &starts, &fql, progress)?,
        SampleLearner::PointMass {
            model,
            vqql: Some(v),
            ..
        } => {
            if !args.quiet {
                eprintln!(
                    "building the codebooks: k-means with {} cells per agent on {} explored states",
                    v.cells, v.samples
                );
            }
            vqql::train_vqql(model, &starts, v, &fql, progress)?.0
        }
        SampleLearner::PointMass { .. } => unreachable!("fql has features, vqql a codebook"),
    };
    bar.finish_and_clear();
    if stop.load(Ordering::SeqCst) {
        return Err(Failure::Interrupted(format!(
            "interrupted after {} episodes; no policy was written",
            outcome.curve.len()
        ))
        .into());
    }
    let seconds = started.elapsed().as_secs_f64();
    match &learner {
        SampleLearner::Khepera(k) => {
            fuzzyq_sim::learn::tasks::khepera::FqlPolicyFile::from_outcome(k, &fql, &outcome)
                .save(&args.out)?;
        }
        SampleLearner::PointMass { model, vqql, .. } => PointMassPolicyFile::from_outcome(
            model.config(),
            &starts,
            &fql,
            vqql.as_ref(),
            &outcome,
        )
        .save(&args.out)?,
    }
    if let Some(p) = &args.curve {
        let mut text = Vec::new();
        fuzzyq_sim::learn::fql::write_curve_csv(&outcome.curve, &mut text)?;
        crate::write_file(p, &text, "curve")?;
    }
    let learner_name = match args.learner {
        LearnerArg::Vqql => "vqql",
        _ => "fql",
    };
    if let Some(p) = &args.plot {
        let title = match &learner {
            SampleLearner::Khepera(_) => {
                format!("Fuzzy Q-learning on two Khepera robots (seed {})", fql.seed)
            }
            SampleLearner::PointMass { model, .. } => format!(
                "{} on {} point masses (seed {})",
                if learner_name == "vqql" {
                    "VQQL"
                } else {
                    "Fuzzy Q-learning"
                },
                model.config().agents,
                fql.seed
            ),
        };
        crate::plot::learning_curve_figure(p, &outcome.curve, &title)?;
    }
    let last_eval = outcome.curve.iter().rev().find_map(|r| r.eval_success_rate);
    #[derive(Serialize)]
    struct FqlSummary {
        env: &'static str,
        learner: &'static str,
        update: fuzzyq_sim::learn::fql::Update,
        policy: String,
        episodes: usize,
        steps_total: usize,
        rewarded_episodes: usize,
        converged_at: Option<usize>,
        final_eval_success_rate: Option<f64>,
        seconds: f64,
        seed: u64,
    }
    if let Some(j) = &args.json {
        write_json(
            j,
            &FqlSummary {
                env,
                learner: learner_name,
                update: fql.update,
                policy: args.out.display().to_string(),
                episodes: outcome.curve.len(),
                steps_total: outcome.steps_total,
                rewarded_episodes: outcome.curve.iter().filter(|r| r.ret > 0.0).count(),
                converged_at: outcome.converged_at,
                final_eval_success_rate: last_eval,
                seconds,
                seed: fql.seed,
            },
        )?;
    }
    if !args.quiet {
        eprintln!(
            "learned in {seconds:.1} s: {} episodes, {} steps ({} met the reward), converged {}, \
             last greedy evaluation success {}; wrote {}",
            outcome.curve.len(),
            outcome.steps_total,
            outcome.curve.iter().filter(|r| r.ret > 0.0).count(),
            outcome
                .converged_at
                .map_or_else(|| "no".to_string(), |e| format!("at episode {e}")),
            last_eval.map_or_else(|| "n/a".to_string(), |s| format!("{:.0}%", 100.0 * s)),
            args.out.display()
        );
    }
    Ok(())
}
