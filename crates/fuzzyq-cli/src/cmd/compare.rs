//! `fuzzyq compare`: the paper's Table 1, rerun on the point-mass task.

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use fuzzyq_sim::compare::{self, CompareConfig, Comparison, Event, Learner};
use fuzzyq_sim::model::pointmass::{RewardShape, Starts};
use fuzzyq_sim::model::{EnvKind, F64Model};

use crate::cmd::load_config;
use crate::output::{self, parse_list, print_stdout, write_file, write_json};
use crate::plot;

#[derive(Args, Debug)]
pub(crate) struct CompareArgs {
    /// The environment (the comparison runs on the point-mass task).
    #[arg(long, value_parser = output::env(), default_value = "pointmass")]
    env: EnvKind,
    /// A TOML configuration (see `fuzzyq config`): the task, the grid of the grid-based
    /// learners and the solver settings (gamma is every learner's discount).
    #[arg(long, value_name = "FILE.toml")]
    config: Option<PathBuf>,
    /// Start of the single rollout, comma-separated [default: the paper's Table 1 start
    /// -4,5,0,0,5,-3,0,0].
    #[arg(long, value_name = "X0", allow_hyphen_values = true)]
    x0: Option<String>,
    /// Rollout length in sample times (for x0 and every random start).
    #[arg(long, value_name = "K", default_value_t = 100)]
    steps: usize,
    /// Number of seeded random starts (at rest) every policy is also rolled out from.
    #[arg(long, value_name = "N", default_value_t = 100)]
    starts: usize,
    /// Seed of the random starts and of the learners from samples.
    #[arg(long, value_name = "S", default_value_t = 7)]
    seed: u64,
    /// Random starts put each agent uniformly within this distance of the goal per axis (m).
    #[arg(long, value_name = "M", default_value_t = 5.0)]
    start_position: f64,
    /// The learners, comma-separated, in table order [default: all].
    #[arg(long, value_name = "L,...", value_delimiter = ',', value_parser = output::named::<Learner>())]
    learners: Option<Vec<Learner>>,
    /// Episodes of the learners from samples (fql, fql-literal, vqql) [default: 3000].
    #[arg(long, value_name = "N")]
    episodes: Option<usize>,
    /// Also a sample-efficiency curve: success over the random starts against these numbers
    /// of transitions (comma-separated), for every named learner that learns from samples
    /// (learned-model, fql, fql-literal, vqql, fqi-samples, vqql-batch), each given that many
    /// transitions of
    /// interaction; writes efficiency.csv, efficiency.json and efficiency.png.
    #[arg(long, value_name = "N,...", value_delimiter = ',')]
    curve: Option<Vec<usize>>,
    /// learned-model: transitions collected on the plant [default: 20000].
    #[arg(long, value_name = "N")]
    samples: Option<usize>,
    /// fqi-samples, vqql-batch: transitions of their batch, collected on the plant with
    /// random actions [default: 100000].
    #[arg(long, value_name = "N")]
    batch_samples: Option<usize>,
    /// fql, fql-literal, vqql: learning episodes start at rest with each agent uniformly
    /// within this distance of the goal per axis (m) [default: the whole field, 6].
    #[arg(long, value_name = "M")]
    learn_position: Option<f64>,
    /// vqql, vqql-batch: k-means cells per agent, this size alone (no sweep).
    #[arg(long, value_name = "K", conflicts_with = "vqql_sweep")]
    cells: Option<usize>,
    /// vqql, vqql-batch: the codebook sizes to sweep (cells per agent, comma-separated); each
    /// one's column is its best size, the whole sweep is reported [default: the powers of two from 16
    /// below the number of own-state fuzzy cores, then that number, at which VQQL has as
    /// many parameters as the additive fuzzy layout].
    #[arg(long, value_name = "K,...", value_delimiter = ',')]
    vqql_sweep: Option<Vec<usize>>,
    /// The reward: the paper's, or shaped by the potential minus each agent's distance to
    /// the goal (potential-based: the optimal policy is the paper's). The learners from
    /// samples learn from it; the learners that plan with the model plan with the paper's,
    /// which gives them the same greedy policy.
    /// [default: the config's, else the paper's]
    #[arg(long, value_name = "REWARD", value_parser = ["paper", "shaped"])]
    reward: Option<String>,
    /// Runs of every learner from samples (fql, fql-literal, vqql, learned-model,
    /// fqi-samples, vqql-batch), seeded
    /// --seed, --seed + 1, ...; the table gives means with 95% bootstrap intervals.
    #[arg(long, value_name = "N", default_value_t = 1)]
    seeds: usize,
    /// Output directory (created if missing): table1.md, table1.csv, table1.json,
    /// paths.png and one rollout figure per learner.
    #[arg(long, value_name = "DIR", default_value = "compare")]
    out: PathBuf,
    /// Refuse runs estimated to need more memory than GB gigabytes [default: 90% of this
    /// machine's memory].
    #[arg(long, value_name = "GB", allow_hyphen_values = true)]
    max_memory: Option<f64>,
    /// No progress output.
    #[arg(long, short)]
    quiet: bool,
}

fn build(args: &CompareArgs) -> anyhow::Result<CompareConfig> {
    if args.env != EnvKind::Pointmass {
        anyhow::bail!(
            "--env {}: the comparison runs on the point-mass task only",
            args.env.name()
        );
    }
    let mut c = CompareConfig {
        steps: args.steps,
        starts: args.starts,
        seed: args.seed,
        start_position: args.start_position,
        ..CompareConfig::new(load_config(args.config.as_deref(), args.env, None)?)
    };
    if let Some(x0) = &args.x0 {
        c.x0 = parse_list(x0, "--x0")?;
    }
    if let Some(learners) = &args.learners {
        c.learners.clone_from(learners);
    }
    if let Some(e) = args.episodes {
        c.fql.episodes = e;
    }
    if let Some(m) = args.learn_position {
        c.fql_starts = Starts::Uniform {
            position: m,
            velocity: 0.0,
        };
    }
    if let Some(k) = args.cells {
        c.vqql.cells = k;
        c.vqql_sweep.clear();
    }
    if let Some(sweep) = &args.vqql_sweep {
        if sweep.is_empty() || sweep.contains(&0) {
            anyhow::bail!("--vqql-sweep: name codebook sizes of at least 1 cell");
        }
        c.vqql_sweep.clone_from(sweep);
    }
    if let Some(reward) = &args.reward {
        c.set_reward(RewardShape::parse(reward, "--reward")?);
    }
    c.seeds = args.seeds;
    c.fql.seed = args.seed;
    c.vqql.seed = args.seed;
    c.model_learning.collection.seed = args.seed;
    if let Some(n) = args.samples {
        c.model_learning.collection.samples = n;
    }
    if let Some(n) = args.batch_samples {
        c.batch.samples = n;
    }
    c.batch.seed = args.seed;
    c.validate()?;
    let task = c.task.build_model()?;
    let mut estimate = output::rollout_estimate(
        c.starts,
        c.steps,
        rayon::current_num_threads(),
        F64Model::state_dim(&task),
        F64Model::actions(&task).dim() * F64Model::n_agents(&task),
    );
    estimate.bytes += fuzzyq_sim::memory::train(&c.task).bytes;
    output::check_memory(args.max_memory, &estimate)?;
    if let Some(budgets) = &args.curve {
        if budgets.is_empty() || budgets.contains(&0) {
            anyhow::bail!("--curve: name numbers of transitions of at least 1");
        }
        if c.learners
            .iter()
            .all(|l| l.is_model_based() && *l != Learner::LearnedModel)
        {
            anyhow::bail!("--curve: none of the learners learns from samples");
        }
    }
    Ok(c)
}

/// The files the comparison writes into the output directory.
fn outputs(dir: &Path, learners: &[Learner], curve: bool) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = ["table1.md", "table1.csv", "table1.json", "paths.png"]
        .iter()
        .map(|f| dir.join(f))
        .collect();
    if curve {
        files.extend(
            ["efficiency.csv", "efficiency.json", "efficiency.png"]
                .iter()
                .map(|f| dir.join(f)),
        );
    }
    files.extend(
        learners
            .iter()
            .map(|l| dir.join(format!("rollout-{}.png", l.name()))),
    );
    files
}

pub(crate) fn run(args: CompareArgs) -> anyhow::Result<()> {
    let config = build(&args)?;
    if args.out.exists() && !args.out.is_dir() {
        anyhow::bail!("--out {} is not a directory", args.out.display());
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create --out {}", args.out.display()))?;
    let files = outputs(&args.out, &config.learners, args.curve.is_some());
    let planned: Vec<(Option<&Path>, &str)> =
        files.iter().map(|f| (Some(f.as_path()), "--out")).collect();
    output::plan(&planned, &[(args.config.as_deref(), "--config")])?;
    let t0 = Instant::now();
    let quiet = args.quiet;
    let comparison = compare::compare(&config, |e| {
        if quiet {
            return;
        }
        match e {
            Event::Training(l) => eprintln!("{}: training ({})", l.name(), l.description()),
            Event::Trained(l, n, s) => {
                let unit = match l {
                    Learner::FqiSamples | Learner::VqqlBatch => "iterations",
                    l if l.is_model_based() => "sweeps",
                    _ => "episodes",
                };
                eprintln!("{}: {n} {unit} in {s:.1} s", l.name());
            }
            Event::Evaluating(l) => eprintln!(
                "{}: rolling out from x0 and {} random starts",
                l.name(),
                config.starts
            ),
            Event::Run {
                learner,
                seed,
                cells,
            } => eprintln!(
                "{}: seed {seed}{}",
                learner.name(),
                cells.map_or(String::new(), |k| format!(", {k} cells per agent"))
            ),
        }
    })?;
    write(&args.out, &comparison)?;
    let table = comparison.to_markdown();
    print_stdout(&table)?;
    if let Some(budgets) = &args.curve {
        let points = compare::sample_efficiency(&config, budgets, |l, n| {
            if !quiet {
                eprintln!("sample-efficiency curve: {} with {n} transitions", l.name());
            }
        })?;
        let fqi = comparison
            .reports
            .iter()
            .find(|r| r.learner == Learner::Fqi)
            .map(|r| ("fqi (the true model)", r.success_rate));
        write_curve(&args.out, &points, fqi, &config)?;
    }
    if !quiet {
        eprintln!(
            "compared {} learners in {:.1} s; wrote {}",
            comparison.reports.len(),
            t0.elapsed().as_secs_f64(),
            files
                .iter()
                .map(|f| f.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}

/// The sample-efficiency curve's files.
fn write_curve(
    dir: &Path,
    points: &[compare::EfficiencyPoint],
    reference: Option<(&str, f64)>,
    config: &CompareConfig,
) -> anyhow::Result<()> {
    let mut csv = String::from(
        "learner,transitions,success_rate,mean_final_error_cm,train_seconds,failure\n",
    );
    for p in points {
        csv.push_str(&format!(
            "{},{},{},{},{},{}\n",
            p.learner.name(),
            p.transitions,
            p.success_rate,
            p.mean_final_error_cm,
            p.train_seconds,
            p.failure.as_deref().unwrap_or("").replace([',', '\n'], ";")
        ));
    }
    write_file(&dir.join("efficiency.csv"), csv.as_bytes())?;
    write_json(&dir.join("efficiency.json"), &points)?;
    let title = format!(
        "Success over {} random starts (seed {}) against transitions of interaction",
        config.starts, config.seed
    );
    plot::efficiency_figure(&dir.join("efficiency.png"), points, reference, &title)
}

fn write(dir: &Path, c: &Comparison) -> anyhow::Result<()> {
    write_file(&dir.join("table1.md"), c.to_markdown().as_bytes())?;
    write_file(&dir.join("table1.csv"), c.to_csv().as_bytes())?;
    write_json(&dir.join("table1.json"), c)?;
    plot::compare_figure(&dir.join("paths.png"), c)?;
    for (r, t) in c.reports.iter().zip(&c.trajectories) {
        let title = format!(
            "{}: {} (greedy policy, T = {} s)",
            r.learner.name(),
            r.learner.description(),
            t.dt
        );
        plot::rollout_figure_titled(
            &dir.join(format!("rollout-{}.png", r.learner.name())),
            t,
            &title,
        )?;
    }
    Ok(())
}
