//! `fuzzyq rollout`.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};
use fuzzyq_sim::io::config::EnvConfig;
use fuzzyq_sim::learn::tasks::khepera::{FqlPolicyFile, fql_success_over_starts, rollout_fql};
use fuzzyq_sim::learn::tasks::pointmass::PointMassPolicyFile;
use fuzzyq_sim::run::policy::{AnyPolicy, PolicyKind};
use fuzzyq_sim::run::robots::{
    KheperaMetrics, KheperaRun, PAPER_KHEPERA_X0, SuccessReport, poses_from_paper, random_starts,
    rollout_khepera_any, success_over_starts,
};
use fuzzyq_sim::run::rollout::{
    PAPER_X0, RolloutMetrics, Trajectory, rollout_additive, rollout_any,
};
use fuzzyq_sim::world::{Collisions, PointMassPlantConfig, rollout_plant};
use fuzzyq_sim::{PolicyArtifact, PolicyFileError};
use serde::Serialize;

use crate::{check_writable, plot, write_file, write_json};

#[derive(Args, Debug)]
pub(crate) struct RolloutArgs {
    /// A policy file written by `fuzzyq train`.
    #[arg(long, value_name = "POLICY")]
    policy: PathBuf,
    /// Initial state, comma-separated [default: the paper's -4,-6,-2,2,5,3,2,-1 for the point
    /// masses, -4,5,0,0,5,3,0,0 for the robots].
    #[arg(long, value_name = "X0", allow_hyphen_values = true)]
    x0: Option<String>,
    /// Khepera: initial headings in degrees, one per robot [default: 0 for every robot].
    #[arg(long, value_name = "DEG,...", allow_hyphen_values = true)]
    headings: Option<String>,
    /// Steps to simulate (one sample time each) [default: 75 for the point masses, 250 for the
    /// robots].
    #[arg(long, value_name = "K")]
    steps: Option<usize>,
    /// Point masses: run on the analytic model or on the rapier plant (discs that collide
    /// with each other and the walls). The robots always run on the rapier plant.
    #[arg(long, value_enum)]
    plant: Option<PlantArg>,
    /// Radius of the point-mass discs on the rapier plant (m) [default: 0.05].
    #[arg(long, value_name = "R")]
    radius: Option<f64>,
    /// Khepera: seed of the plant's noise (and of the random starts with --starts) [default: 0].
    #[arg(long, value_name = "S")]
    seed: Option<u64>,
    /// Khepera: instead of one run, roll out from N seeded random starts and report the
    /// success rate (--plot draws the starts, --json writes every run's metrics).
    #[arg(long, value_name = "N")]
    starts: Option<usize>,
    /// Greedy (eq 7) or interpolated (eq 22) policy.
    #[arg(long, value_enum, default_value_t = KindArg::Greedy)]
    policy_kind: KindArg,
    /// Write the trajectory as CSV.
    #[arg(long, value_name = "FILE.csv")]
    csv: Option<PathBuf>,
    /// Draw states and forces over time per agent and the paths in the plane (PNG or SVG).
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    plot: Option<PathBuf>,
    /// dcmotor, pendulum: draw the value function and the policy as heat maps over the state
    /// space (PNG or SVG).
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    maps: Option<PathBuf>,
    /// Write the metrics as JSON.
    #[arg(long, value_name = "METRICS.json")]
    json: Option<PathBuf>,
    /// Print nothing on success.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum PlantArg {
    /// The analytic model the policy was trained on.
    Model,
    /// rapier2d rigid bodies.
    Rapier,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
enum KindArg {
    Greedy,
    Interpolated,
}

/// Parses `-4,-6,-2,2` (also with spaces or surrounding brackets) given to `flag`.
pub(crate) fn parse_list(text: &str, flag: &str) -> anyhow::Result<Vec<f64>> {
    let t = text.trim().trim_start_matches('[').trim_end_matches(']');
    t.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .enumerate()
        .map(|(i, s)| {
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .with_context(|| format!("{flag}: value {} ({s:?}) is not a finite number", i + 1))
        })
        .collect()
}

fn csv(t: &Trajectory, action_names: [&str; 2]) -> String {
    let mut out = String::from("t");
    for i in 1..=t.agents {
        for v in ["sx", "sy", "vx", "vy"] {
            let _ = write!(out, ",{v}{i}");
        }
    }
    for i in 1..=t.agents {
        let _ = write!(out, ",{}{i},{}{i}", action_names[0], action_names[1]);
    }
    out.push_str(",reward\n");
    for (k, x) in t.states.iter().enumerate() {
        let _ = write!(out, "{}", t.time(k));
        for v in x {
            let _ = write!(out, ",{v}");
        }
        match (t.actions.get(k), t.rewards.get(k)) {
            (Some(u), Some(r)) => {
                for v in u {
                    let _ = write!(out, ",{v}");
                }
                let _ = write!(out, ",{r}");
            }
            _ => out.push_str(&",".repeat(2 * t.agents + 1)),
        }
        out.push('\n');
    }
    out
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or_else(|| "never".into(), |t| format!("{t:.1} s"))
}

fn report(m: &RolloutMetrics) -> String {
    let agents: Vec<String> = (0..m.final_error_m.len())
        .map(|i| {
            format!(
                "agent {}: arrives {}, final error {:.1} cm",
                i + 1,
                fmt_opt(m.arrival_time_s[i]),
                m.final_error_m[i] * 100.0
            )
        })
        .collect();
    format!(
        "{} policy, {} steps of {} s: reward region reached {}; {}; return {:.3}, V(x0) {:.3}\n",
        m.policy_kind.name(),
        m.steps,
        m.dt,
        fmt_opt(m.reach_time_s),
        agents.join("; "),
        m.discounted_return,
        m.value_x0
    )
}

/// The point-mass metrics on the rapier plant: the model's metrics plus collisions.
#[derive(Serialize)]
struct PlantMetrics<'a> {
    #[serde(flatten)]
    metrics: &'a RolloutMetrics,
    plant: &'static str,
    collisions: &'a Collisions,
}

pub(crate) fn run(args: RolloutArgs) -> anyhow::Result<()> {
    for (path, what) in [
        (&args.csv, "CSV"),
        (&args.plot, "plot"),
        (&args.json, "metrics"),
    ] {
        if let Some(p) = path {
            check_writable(p, what)?;
        }
    }
    if let Some(p) = &args.plot {
        plot::check_extension(p)?;
    }
    if args.steps == Some(0) {
        anyhow::bail!("--steps must be at least 1");
    }
    let artifact = match PolicyArtifact::load(&args.policy) {
        Ok(a) => a,
        // Not a `.fzq` file: a fuzzy Q-learning policy (`train --learner fql`) is TOML.
        Err(e @ PolicyFileError::NotAPolicy { .. }) => {
            if args.policy_kind != KindArg::Greedy {
                anyhow::bail!(
                    "--policy-kind: a policy learned from samples (fql, vqql) acts greedily \
                     (decentralised)"
                );
            }
            if let Ok(file) = FqlPolicyFile::load(&args.policy) {
                let config = file.config.clone();
                return khepera(args, &Robots::Fql(Box::new(file)), &config);
            }
            let Ok(file) = PointMassPolicyFile::load(&args.policy) else {
                return Err(e.into());
            };
            let agents = file.config.agents;
            return point_mass(args, PointMasses::Additive(Box::new(file)), agents);
        }
        Err(e) => return Err(e.into()),
    };
    match artifact.config.env.clone() {
        EnvConfig::Pointmass(p) => point_mass(
            args,
            PointMasses::Fqi(Box::new(AnyPolicy::from_artifact(artifact)?)),
            p.agents,
        ),
        EnvConfig::Khepera(k) => {
            let policy = AnyPolicy::from_artifact(artifact)?;
            khepera(args, &Robots::Fqi(Box::new(policy)), &k)
        }
        EnvConfig::Dcmotor(_)
        | EnvConfig::Pendulum(_)
        | EnvConfig::Carhill(_)
        | EnvConfig::Arm(_) => classic(args, artifact),
    }
}

/// Runs `$body` with `$p` bound to the policy of either precision.
macro_rules! with_policy {
    ($policy:expr, $p:ident => $body:expr) => {
        match $policy {
            AnyPolicy::F32($p) => $body,
            AnyPolicy::F64($p) => $body,
        }
    };
}

/// A classic benchmark's state and action names (figures, CSV) and its default start.
fn classic_names(env: &str) -> (Vec<&'static str>, Vec<&'static str>, Vec<f64>) {
    use std::f64::consts::PI;
    match env {
        "pendulum" => (
            vec!["angle (rad, 0 = up)", "angular velocity (rad/s)"],
            vec!["voltage (V)"],
            vec![-PI, 0.0],
        ),
        "carhill" => (
            vec!["position (m)", "velocity (m/s)"],
            vec!["force (N)"],
            vec![-0.5, 0.0],
        ),
        "arm" => (
            vec![
                "angle 1 (rad)",
                "angular velocity 1 (rad/s)",
                "angle 2 (rad)",
                "angular velocity 2 (rad/s)",
            ],
            vec!["torque 1 (N m)", "torque 2 (N m)"],
            vec![-1.0, 0.0, 1.0, 0.0],
        ),
        _ => (
            vec!["angle (rad)", "angular velocity (rad/s)"],
            vec!["voltage (V)"],
            vec![-PI, 0.0],
        ),
    }
}

/// `fuzzyq rollout` on a classic benchmark's policy: one run (figure, CSV, metrics), the
/// Monte-Carlo evaluation over a lattice of starts (`--starts N`), and heat maps of the value
/// function and the policy (`--maps`).
fn classic(args: RolloutArgs, artifact: PolicyArtifact) -> anyhow::Result<()> {
    let env = artifact.config.env.name();
    for (set, flag) in [
        (args.headings.is_some(), "--headings"),
        (args.plant.is_some(), "--plant"),
        (args.radius.is_some(), "--radius"),
        (args.seed.is_some(), "--seed"),
    ] {
        if set {
            anyhow::bail!("{flag} does not apply to {env} policies");
        }
    }
    let (state_names, action_names, default_x0) = classic_names(env);
    if let Some(p) = &args.maps {
        if state_names.len() != 2 {
            anyhow::bail!(
                "--maps draws 2-D state spaces; the {env} state has {} variables",
                state_names.len()
            );
        }
        plot::check_extension(p)?;
        check_writable(p, "maps")?;
    }
    let kind = kind_of(&args);
    // The toolbox's replays: 2 s for the motor, 3 s for the pendulum; 10 s for the car and
    // the arm.
    let steps = args.steps.unwrap_or(match env {
        "pendulum" => 600,
        "carhill" => 100,
        "arm" => 200,
        _ => 400,
    });
    let policy = AnyPolicy::from_artifact(artifact)?;
    if let Some(p) = &args.maps {
        let maps = with_policy!(&policy, p => value_and_policy_maps(p, kind)?);
        plot::heat_maps_figure(
            p,
            &format!("{env}: value function and {} policy", kind.name()),
            (state_names[0], state_names[1]),
            &maps,
        )?;
    }
    if let Some(n) = args.starts {
        if args.x0.is_some() || args.csv.is_some() || args.plot.is_some() {
            anyhow::bail!(
                "--starts evaluates over a lattice of starts; --x0, --csv and --plot apply to one run"
            );
        }
        let mc = with_policy!(&policy, p => {
            let starts = fuzzyq_sim::run::evaluate::lattice(p.model(), n)?;
            fuzzyq_sim::run::evaluate::monte_carlo(p, &starts, steps, kind)?
        });
        if let Some(p) = &args.json {
            write_json(p, &mc)?;
        }
        if !args.quiet {
            crate::print_stdout(&format!(
                "{} policy, {} starts ({n} per state variable, over the state bounds), {steps} \
                 steps each: mean discounted return {:.4} (min {:.4}, max {:.4})\n",
                kind.name(),
                mc.runs.len(),
                mc.mean_return,
                mc.min_return,
                mc.max_return
            ))?;
        }
        return Ok(());
    }
    let x0 = match &args.x0 {
        Some(t) => parse_list(t, "--x0")?,
        None => default_x0,
    };
    let (t, run) = with_policy!(&policy, p => fuzzyq_sim::run::evaluate::run(p, &x0, steps, kind)?);
    if let Some(p) = &args.csv {
        let mut out = String::from("t");
        for i in 1..=state_names.len() {
            let _ = write!(out, ",x{i}");
        }
        for i in 1..=action_names.len() {
            let _ = write!(out, ",u{i}");
        }
        out.push_str(",reward\n");
        for (k, x) in t.states.iter().enumerate() {
            let _ = write!(out, "{}", t.time(k));
            for v in x {
                let _ = write!(out, ",{v}");
            }
            match (t.actions.get(k), t.rewards.get(k)) {
                (Some(u), Some(r)) => {
                    for v in u {
                        let _ = write!(out, ",{v}");
                    }
                    let _ = writeln!(out, ",{r}");
                }
                _ => {
                    out.push_str(&",".repeat(action_names.len() + 1));
                    out.push('\n');
                }
            }
        }
        write_file(p, out.as_bytes(), "CSV")?;
    }
    if let Some(p) = &args.plot {
        let title = format!("{env} ({} policy, T = {} s)", kind.name(), t.dt);
        plot::series_figure(p, &t, &title, &state_names, &action_names)?;
    }
    if let Some(p) = &args.json {
        write_json(p, &run)?;
    }
    if !args.quiet {
        crate::print_stdout(&format!(
            "{} policy, {} steps of {} s from {x0:?}{}: discounted return {:.4}, final state \
             {:?}, V(x0) {:.4}\n",
            kind.name(),
            run.steps,
            t.dt,
            if run.terminal {
                " (ended in a terminal state)"
            } else {
                ""
            },
            run.discounted_return,
            run.final_state,
            run.value_x0
        ))?;
    }
    Ok(())
}

/// `V` and the policy's action sampled on a 101 x 101 lattice over a 2-D state space.
fn value_and_policy_maps<T: fuzzyq_core::Real>(
    p: &fuzzyq_sim::run::policy::Policy<T>,
    kind: PolicyKind,
) -> anyhow::Result<Vec<plot::HeatMap>>
where
    fuzzyq_sim::model::EnvModel: fuzzyq_core::Model<T>,
{
    use fuzzyq_core::Model;
    const N: usize = 101;
    let model = p.model();
    let axis = |d: usize| {
        let (lo, hi) = Model::<f64>::state_bounds(model, d);
        (0..N)
            .map(|i| lo + (hi - lo) * i as f64 / (N - 1) as f64)
            .collect::<Vec<f64>>()
    };
    let (xs, ys) = (axis(0), axis(1));
    let mut actor = p.actor(kind)?;
    let mut u = vec![0.0; actor.action_dim()];
    let (mut v, mut a) = (Vec::with_capacity(N * N), Vec::with_capacity(N * N));
    for &y in &ys {
        for &x in &xs {
            v.push(p.value(&[x, y])?);
            actor.act(&[x, y], &mut u)?;
            a.push(u[0]);
        }
    }
    Ok(vec![
        plot::HeatMap {
            caption: "V(x)".into(),
            xs: xs.clone(),
            ys: ys.clone(),
            values: v,
        },
        plot::HeatMap {
            caption: format!("{} action", kind.name()),
            xs,
            ys,
            values: a,
        },
    ])
}

/// A trained point-mass policy: fuzzy Q-iteration, or a learner from samples.
enum PointMasses {
    /// Joint fuzzy Q-iteration.
    Fqi(Box<AnyPolicy>),
    /// Fuzzy Q-learning or VQQL (additive layout).
    Additive(Box<PointMassPolicyFile>),
}

/// A trained Khepera policy of either learner.
enum Robots {
    /// Joint fuzzy Q-iteration.
    Fqi(Box<AnyPolicy>),
    /// Model-free fuzzy Q-learning.
    Fql(Box<FqlPolicyFile>),
}

impl Robots {
    fn run(
        &self,
        start: &[[f64; 3]],
        steps: usize,
        kind: PolicyKind,
        seed: u64,
    ) -> anyhow::Result<(KheperaRun, KheperaMetrics)> {
        Ok(match self {
            Self::Fqi(p) => rollout_khepera_any(p, start, steps, kind, seed)?,
            Self::Fql(f) => rollout_fql(&f.q, &f.config, start, steps, seed, f.fql.gamma)?,
        })
    }

    fn starts(
        &self,
        n: usize,
        seed: u64,
        steps: usize,
        kind: PolicyKind,
    ) -> anyhow::Result<(SuccessReport, Vec<KheperaMetrics>)> {
        Ok(match self {
            Self::Fqi(p) => success_over_starts(p, n, seed, steps, kind)?,
            Self::Fql(f) => fql_success_over_starts(&f.q, &f.config, n, seed, steps, f.fql.gamma)?,
        })
    }
}

fn kind_of(args: &RolloutArgs) -> PolicyKind {
    match args.policy_kind {
        KindArg::Greedy => PolicyKind::Greedy,
        KindArg::Interpolated => PolicyKind::Interpolated,
    }
}

fn point_mass(args: RolloutArgs, policy: PointMasses, agents: usize) -> anyhow::Result<()> {
    if args.maps.is_some() {
        anyhow::bail!("--maps applies to dcmotor and pendulum policies only");
    }
    for (set, flag) in [
        (args.headings.is_some(), "--headings"),
        (args.starts.is_some(), "--starts"),
        (args.seed.is_some(), "--seed"),
    ] {
        if set {
            anyhow::bail!("{flag} applies to khepera policies only");
        }
    }
    if args.radius.is_some() && args.plant != Some(PlantArg::Rapier) {
        anyhow::bail!("--radius applies to --plant rapier only");
    }
    let x0 = match &args.x0 {
        Some(t) => parse_list(t, "--x0")?,
        None if agents == 2 => PAPER_X0.to_vec(),
        None => anyhow::bail!(
            "the policy has {agents} agents; give --x0 with {} values (the default start is the \
             paper's, for 2 agents)",
            4 * agents
        ),
    };
    let kind = kind_of(&args);
    let steps = args.steps.unwrap_or(75);
    let policy = match policy {
        PointMasses::Fqi(p) => p,
        PointMasses::Additive(file) => {
            if args.plant == Some(PlantArg::Rapier) {
                anyhow::bail!("--plant rapier runs fuzzy Q-iteration policies only");
            }
            let model = file.validate()?;
            let (t, m) = rollout_additive(&model, &file.q, &x0, steps, file.fql.gamma)?;
            return point_mass_outputs(&args, &t, &m, None, kind);
        }
    };
    let (trajectory, metrics, collisions) = match args.plant.unwrap_or(PlantArg::Model) {
        PlantArg::Model => {
            let (t, m) = rollout_any(&policy, &x0, steps, kind)?;
            (t, m, None)
        }
        PlantArg::Rapier => {
            let plant = PointMassPlantConfig {
                radius: args
                    .radius
                    .unwrap_or(PointMassPlantConfig::default().radius),
                ..PointMassPlantConfig::default()
            };
            let (t, m, c) = match &*policy {
                AnyPolicy::F32(p) => rollout_plant(p, &x0, steps, kind, &plant)?,
                AnyPolicy::F64(p) => rollout_plant(p, &x0, steps, kind, &plant)?,
            };
            (t, m, Some(c))
        }
    };
    point_mass_outputs(&args, &trajectory, &metrics, collisions.as_ref(), kind)
}

/// Writes a point-mass rollout's CSV, figure and metrics, and prints its report.
fn point_mass_outputs(
    args: &RolloutArgs,
    trajectory: &Trajectory,
    metrics: &RolloutMetrics,
    collisions: Option<&Collisions>,
    kind: PolicyKind,
) -> anyhow::Result<()> {
    if let Some(p) = &args.csv {
        write_file(p, csv(trajectory, ["ux", "uy"]).as_bytes(), "CSV")?;
    }
    if let Some(p) = &args.plot {
        plot::rollout_figure(p, trajectory, kind)?;
    }
    if let Some(p) = &args.json {
        match collisions {
            None => write_json(p, metrics)?,
            Some(c) => write_json(
                p,
                &PlantMetrics {
                    metrics,
                    plant: "rapier",
                    collisions: c,
                },
            )?,
        }
    }
    if !args.quiet {
        let mut text = report(metrics);
        if let Some(c) = collisions {
            let _ = writeln!(text, "rapier plant: {} collisions", c.total);
        }
        crate::print_stdout(&text)?;
    }
    Ok(())
}

fn khepera(
    args: RolloutArgs,
    policy: &Robots,
    config: &fuzzyq_sim::model::khepera::KheperaConfig,
) -> anyhow::Result<()> {
    if args.plant == Some(PlantArg::Model) {
        anyhow::bail!("--plant model: khepera policies run on the rapier plant only");
    }
    if args.maps.is_some() {
        anyhow::bail!("--maps applies to dcmotor and pendulum policies only");
    }
    if args.radius.is_some() {
        anyhow::bail!("--radius applies to point-mass policies on --plant rapier only");
    }
    let seed = args.seed.unwrap_or(0);
    let kind = kind_of(&args);
    let steps = args.steps.unwrap_or(250);
    if let Some(n) = args.starts {
        if n == 0 {
            anyhow::bail!("--starts must be at least 1");
        }
        if args.x0.is_some() || args.headings.is_some() || args.csv.is_some() {
            anyhow::bail!(
                "--starts draws random starts; it cannot be combined with --x0, --headings or --csv"
            );
        }
        let (report, runs) = policy.starts(n, seed, steps, kind)?;
        if let Some(p) = &args.plot {
            let starts = random_starts(config, n, seed)?;
            let ok: Vec<bool> = runs.iter().map(|m| m.success).collect();
            plot::success_figure(
                p,
                &starts,
                &ok,
                &config.arena,
                &format!(
                    "{} policy: {} of {} random starts succeed (seed {})",
                    kind.name(),
                    report.successes,
                    n,
                    seed
                ),
            )?;
        }
        if let Some(p) = &args.json {
            #[derive(Serialize)]
            struct Out<'a> {
                #[serde(flatten)]
                report: &'a SuccessReport,
                policy_kind: PolicyKind,
                steps: usize,
                runs: &'a [KheperaMetrics],
            }
            write_json(
                p,
                &Out {
                    report: &report,
                    policy_kind: kind,
                    steps,
                    runs: &runs,
                },
            )?;
        }
        if !args.quiet {
            crate::print_stdout(&format!(
                "{} policy, {n} random starts (seed {}), {steps} steps of {} s: {} succeed ({:.0}%), \
                 {} with collisions, mean time to the reward region {}, mean final ||x|| {:.3}\n",
                kind.name(),
                seed,
                config.sample_time,
                report.successes,
                100.0 * report.success_rate,
                report.runs_with_collisions,
                fmt_opt(report.mean_reach_time_s),
                report.mean_final_norm,
            ))?;
        }
        return Ok(());
    }
    let x0 = match &args.x0 {
        Some(t) => parse_list(t, "--x0")?,
        None if config.agents == 2 => PAPER_KHEPERA_X0.to_vec(),
        None => anyhow::bail!(
            "the policy has {} robots; give --x0 with {} values",
            config.agents,
            4 * config.agents
        ),
    };
    let headings = match &args.headings {
        Some(t) => parse_list(t, "--headings")?,
        None => vec![0.0; config.agents],
    };
    let start = poses_from_paper(config, &x0, &headings)?;
    let (run, metrics) = policy.run(&start, steps, kind, seed)?;
    if let Some(p) = &args.csv {
        write_file(p, csv(&run.trajectory, ["vl", "vr"]).as_bytes(), "CSV")?;
    }
    if let Some(p) = &args.plot {
        plot::khepera_figure(
            p,
            &run,
            &config.arena,
            config.radius,
            kind,
            &format!(
                "Khepera IV robots, {} policy on the rapier plant: {}",
                kind.name(),
                if metrics.success {
                    "both arrive, no collision"
                } else {
                    "not successful"
                }
            ),
        )?;
    }
    if let Some(p) = &args.json {
        write_json(p, &metrics)?;
    }
    if !args.quiet {
        let mut text = report(&metrics.rollout);
        let _ = writeln!(
            text,
            "rapier plant: {} collisions; final ||x|| {:.3} ({} the reward region)",
            metrics.collisions.total,
            metrics.final_norm,
            if metrics.final_norm < config.goal_radius {
                "inside"
            } else {
                "outside"
            }
        );
        crate::print_stdout(&text)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_x0_forms() {
        assert_eq!(
            parse_list("-4,-6,2", "--x0").unwrap(),
            vec![-4.0, -6.0, 2.0]
        );
        assert_eq!(parse_list("[1, 2.5]", "--x0").unwrap(), vec![1.0, 2.5]);
        let e = parse_list("1,x", "--headings").unwrap_err().to_string();
        assert!(e.starts_with("--headings: value 2"), "{e}");
        assert!(parse_list("1,nan", "--x0").is_err());
    }
}
