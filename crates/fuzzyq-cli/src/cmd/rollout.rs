//! `fuzzyq rollout`: any policy file, one start or many, on the plant of its environment.
//!
//! What applies to which policy (plants, headings, maps, the default start and length) comes
//! from the environment registry ([`EnvKind::spec`]); the runs themselves are the library's
//! ([`fuzzyq_sim::run::evaluate`]).

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::{Args, ValueEnum};
use fuzzyq_core::q::PolicyKind;
use fuzzyq_sim::model::khepera::random_starts;
use fuzzyq_sim::model::pointmass::{START_POSITION, random_starts as point_mass_starts};
use fuzzyq_sim::model::{Dynamics, EnvKind, EnvModel, EnvSpec, F64Model, StartsKind};
use fuzzyq_sim::run::evaluate::{self, Outcome, PlantChoice, RolloutSpec};
use fuzzyq_sim::run::metrics::{PointMassReport, RolloutMetrics, Trajectory};
use fuzzyq_sim::run::policy::Policy;
use fuzzyq_sim::world::{Collisions, PointMassPlantConfig};
use serde::Serialize;

use crate::output::{self, parse_list, print_stdout, refuse, write_file, write_json};
use crate::plot;

#[derive(Args, Debug)]
pub(crate) struct RolloutArgs {
    /// A policy file written by `fuzzyq train` (any learner).
    #[arg(long, value_name = "POLICY")]
    policy: PathBuf,
    /// Initial state, comma-separated (for the robots the paper's state, or their poses x,y,heading
    /// per robot) [default: the environment's; for the point masses the paper's
    /// -4,-6,-2,2,5,3,2,-1, for the robots -4,5,0,0,5,3,0,0].
    #[arg(long, value_name = "X0", allow_hyphen_values = true)]
    x0: Option<String>,
    /// Khepera: initial headings in degrees, one per robot [default: 0 for every robot].
    #[arg(long, value_name = "DEG,...", allow_hyphen_values = true)]
    headings: Option<String>,
    /// Steps to simulate (one sample time each) [default: the environment's; 75 for the point
    /// masses, 250 for the robots].
    #[arg(long, value_name = "K")]
    steps: Option<usize>,
    /// Point masses: run on the analytic model or on the rapier plant (discs that collide
    /// with each other and the walls). The robots always run on the rapier plant.
    #[arg(long, value_enum)]
    plant: Option<PlantArg>,
    /// Radius of the point-mass discs on the rapier plant (m) [default: 0.05].
    #[arg(long, value_name = "R")]
    radius: Option<f64>,
    /// Seed of the robots' plant noise, and of the random starts with --starts [default: 0].
    #[arg(long, value_name = "S")]
    seed: Option<u64>,
    /// Instead of one run, roll out from N starts: seeded random starts at rest with their
    /// success rate (robots, point masses), or an N^E lattice over the state bounds with the
    /// mean discounted return (classic benchmarks). --plot draws the robots' starts, --json
    /// writes every run.
    #[arg(long, value_name = "N")]
    starts: Option<usize>,
    /// The policy: greedy (eq 7) or interpolated (eq 22).
    #[arg(long, value_parser = output::named::<PolicyKind>(), default_value = "greedy")]
    policy_kind: PolicyKind,
    /// Write the trajectory as CSV.
    #[arg(long, value_name = "FILE.csv")]
    csv: Option<PathBuf>,
    /// Draw states and actions over time per agent (and the paths in the plane) as PNG or SVG.
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    plot: Option<PathBuf>,
    /// 2-D state spaces: draw the value function and the policy as heat maps (PNG or SVG).
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    maps: Option<PathBuf>,
    /// Write the metrics as JSON.
    #[arg(long, value_name = "METRICS.json")]
    json: Option<PathBuf>,
    /// Refuse runs estimated to need more memory than GB gigabytes [default: 90% of this
    /// machine's memory].
    #[arg(long, value_name = "GB", allow_hyphen_values = true)]
    max_memory: Option<f64>,
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

pub(crate) fn run(args: RolloutArgs) -> anyhow::Result<()> {
    output::plan(
        &[
            (args.csv.as_deref(), "--csv"),
            (args.plot.as_deref(), "--plot"),
            (args.json.as_deref(), "--json"),
            (args.maps.as_deref(), "--maps"),
        ],
        &[(Some(&args.policy), "--policy")],
    )?;
    for (p, flag) in [(&args.plot, "--plot"), (&args.maps, "--maps")] {
        if let Some(p) = p {
            plot::check_extension(p, flag)?;
        }
    }
    if args.steps == Some(0) {
        anyhow::bail!("--steps must be at least 1");
    }
    // The physics engine runs in single precision: 1e39 would be an infinite disc.
    if let Some(r) = args.radius
        && !(r > 0.0 && r <= f64::from(f32::MAX))
    {
        anyhow::bail!("--radius: expected a positive number within single precision, got {r}");
    }
    let policy = Policy::load(&args.policy)?;
    let Some(model) = policy.model() else {
        anyhow::bail!("--policy: a policy of a tabulated model has no plant to run on");
    };
    let env = model.kind();
    let spec = env.spec();
    check_flags(&args, env, spec, model)?;
    // Refuse a policy kind the policy does not have before any work, naming the flag.
    if policy.controller(args.policy_kind).is_err() {
        anyhow::bail!(
            "--policy-kind: a policy learned from samples (fql, vqql) acts greedily \
             (decentralised); leave --policy-kind greedy"
        );
    }
    let steps = args.steps.unwrap_or(spec.default_steps);
    let seed = args.seed.unwrap_or(0);
    output::check_memory(
        args.max_memory,
        &output::rollout_estimate(
            args.starts.unwrap_or(1),
            steps,
            rayon::current_num_threads(),
            F64Model::state_dim(model),
            F64Model::actions(model).dim() * F64Model::n_agents(model),
        ),
    )?;
    if let Some(p) = &args.maps {
        maps(&policy, model, p, args.policy_kind)?;
    }
    if let Some(n) = args.starts {
        return many_starts(&args, &policy, model, n, steps, seed);
    }
    one_start(&args, &policy, model, steps, seed)
}

/// One rollout from `--x0` (or the environment's default start): its trajectory, figure,
/// metrics and report.
fn one_start(
    args: &RolloutArgs,
    policy: &Policy,
    model: &EnvModel,
    steps: usize,
    seed: u64,
) -> anyhow::Result<()> {
    let spec = model.kind().spec();
    let env = model.kind();
    let x0 = args
        .x0
        .as_deref()
        .map(|t| parse_list(t, "--x0"))
        .transpose()?;
    let headings = args
        .headings
        .as_deref()
        .map(|t| parse_list(t, "--headings"))
        .transpose()?;
    let start = evaluate::start_for(model, x0, headings.as_deref())?;
    let plant = match args.plant {
        Some(PlantArg::Rapier) => PlantChoice::Rapier(PointMassPlantConfig {
            radius: args
                .radius
                .unwrap_or(PointMassPlantConfig::default().radius),
            ..PointMassPlantConfig::default()
        }),
        _ => PlantChoice::Model,
    };
    let rollout = RolloutSpec {
        kind: args.policy_kind,
        steps,
        plant,
        seed,
    };
    match evaluate::run(policy, &start, &rollout)? {
        Outcome::PointMass {
            trajectory,
            metrics,
            collisions,
        } => point_mass_outputs(args, spec, &trajectory, &metrics, collisions.as_ref()),
        Outcome::Khepera { run, metrics } => {
            let EnvModel::Khepera(k) = model else {
                unreachable!("a robot run comes from a robot policy")
            };
            let config = k.config();
            if let Some(p) = &args.csv {
                write_file(p, csv(&run.trajectory, spec).as_bytes())?;
            }
            if let Some(p) = &args.plot {
                let kind = args.policy_kind;
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
                print_stdout(&text)?;
            }
            Ok(())
        }
        Outcome::Classic {
            trajectory,
            summary,
        } => {
            let kind = args.policy_kind;
            if let Some(p) = &args.csv {
                write_file(p, csv(&trajectory, spec).as_bytes())?;
            }
            if let Some(p) = &args.plot {
                let title = format!("{env} ({} policy, T = {} s)", kind.name(), trajectory.dt);
                plot::series_figure(
                    p,
                    &trajectory,
                    &title,
                    spec.state_labels,
                    spec.action_labels,
                )?;
            }
            if let Some(p) = &args.json {
                write_json(p, &summary)?;
            }
            if !args.quiet {
                print_stdout(&format!(
                    "{} policy, {} steps of {} s from {start:?}{}: discounted return {:.4}, final \
                     state {:?}, V(x0) {:.4}\n",
                    kind.name(),
                    summary.steps,
                    trajectory.dt,
                    if summary.terminal {
                        " (ended in a terminal state)"
                    } else {
                        ""
                    },
                    summary.discounted_return,
                    summary.final_state,
                    summary.value_x0
                ))?;
            }
            Ok(())
        }
    }
}

/// Refuses the flags that do not apply to the policy's environment, with the registry's word.
fn check_flags(
    args: &RolloutArgs,
    env: EnvKind,
    spec: &EnvSpec,
    model: &EnvModel,
) -> anyhow::Result<()> {
    let not_for = format!("does not apply to {env} policies");
    refuse(
        args.headings.is_some() && !spec.robot_plant,
        "--headings",
        "applies to khepera policies only",
    )?;
    match args.plant {
        Some(PlantArg::Model) if spec.robot_plant => {
            anyhow::bail!("--plant model: khepera policies run on the rapier plant only")
        }
        Some(_) if spec.classic => refuse(true, "--plant", &not_for)?,
        _ => {}
    }
    refuse(
        args.radius.is_some() && args.plant != Some(PlantArg::Rapier),
        "--radius",
        "applies to point-mass policies on --plant rapier only",
    )?;
    refuse(
        args.seed.is_some() && !spec.robot_plant && !(args.starts.is_some() && spec.multi_agent),
        "--seed",
        "seeds the robots' plant and the random starts of --starts; it does not apply here",
    )?;
    let dim = F64Model::state_dim(model);
    refuse(
        args.maps.is_some() && dim != 2,
        "--maps",
        &format!("draws 2-D state spaces; the {env} state has {dim} variables"),
    )?;
    if args.starts.is_some() {
        refuse(args.starts == Some(0), "--starts", "must be at least 1")?;
        let one_run = match spec.starts {
            StartsKind::Random => {
                args.x0.is_some()
                    || args.headings.is_some()
                    || args.csv.is_some()
                    || (args.plot.is_some() && !spec.robot_plant)
            }
            StartsKind::Lattice => args.x0.is_some() || args.csv.is_some() || args.plot.is_some(),
        };
        refuse(
            one_run,
            "--starts",
            "evaluates many starts; --x0, --headings, --csv and (except for the robots' starts \
             figure) --plot apply to one run",
        )?;
        refuse(
            args.plant == Some(PlantArg::Rapier),
            "--starts",
            "runs on the model (the robots on their plant); --plant rapier applies to one run",
        )?;
    }
    Ok(())
}

/// The trajectory as CSV: time, the state's and the action's variables (suffixed by the agent
/// number for multi-agent tasks) and the reward.
fn csv(t: &Trajectory, spec: &EnvSpec) -> String {
    let columns = |names: &[&str]| -> Vec<String> {
        if spec.multi_agent {
            (1..=t.agents)
                .flat_map(|i| names.iter().map(move |n| format!("{n}{i}")))
                .collect()
        } else {
            names.iter().map(|n| (*n).to_string()).collect()
        }
    };
    let (states, actions) = (columns(spec.state_names), columns(spec.action_names));
    let mut out = String::from("t");
    for c in states.iter().chain(&actions) {
        let _ = write!(out, ",{c}");
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
            _ => out.push_str(&",".repeat(actions.len() + 1)),
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

/// Writes a point-mass rollout's CSV, figure and metrics, and prints its report.
fn point_mass_outputs(
    args: &RolloutArgs,
    spec: &EnvSpec,
    trajectory: &Trajectory,
    metrics: &RolloutMetrics,
    collisions: Option<&Collisions>,
) -> anyhow::Result<()> {
    if let Some(p) = &args.csv {
        write_file(p, csv(trajectory, spec).as_bytes())?;
    }
    if let Some(p) = &args.plot {
        plot::rollout_figure(p, trajectory, args.policy_kind)?;
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
        print_stdout(&text)?;
    }
    Ok(())
}

/// The JSON of `--starts` for the robots and the point masses: the task's report, the
/// settings and every run's metrics.
#[derive(Serialize)]
struct StartsJson<'a, R, M> {
    #[serde(flatten)]
    report: &'a R,
    #[serde(skip_serializing_if = "Option::is_none")]
    seed: Option<u64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    start_position: Option<f64>,
    policy_kind: PolicyKind,
    steps: usize,
    runs: &'a [M],
}

impl<'a, R, M> StartsJson<'a, R, M> {
    fn new(report: &'a R, policy_kind: PolicyKind, steps: usize, runs: &'a [M]) -> Self {
        Self {
            report,
            seed: None,
            start_position: None,
            policy_kind,
            steps,
            runs,
        }
    }
}

/// `--starts N`: many runs of the policy, as its task evaluates them.
fn many_starts(
    args: &RolloutArgs,
    policy: &Policy,
    model: &EnvModel,
    n: usize,
    steps: usize,
    seed: u64,
) -> anyhow::Result<()> {
    let kind = args.policy_kind;
    match model {
        EnvModel::Khepera(k) => {
            let config = k.config();
            let (report, runs) = evaluate::khepera_starts(policy, n, seed, steps, kind)?;
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
                write_json(p, &StartsJson::new(&report, kind, steps, &runs))?;
            }
            if !args.quiet {
                print_stdout(&format!(
                    "{} policy, {n} random starts (seed {}), {steps} steps of {} s: {} succeed \
                     ({:.0}%), {} with collisions, mean time to the reward region {}, mean \
                     final ||x|| {:.3}\n",
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
        }
        EnvModel::PointMass(pm) => {
            let starts = point_mass_starts(pm, n, seed, START_POSITION)?;
            let runs = evaluate::point_mass_starts(policy, &starts, steps, kind)?;
            let report = PointMassReport::from_runs(&runs);
            if let Some(p) = &args.json {
                let json = StartsJson {
                    seed: Some(seed),
                    start_position: Some(START_POSITION),
                    ..StartsJson::new(&report, kind, steps, &runs)
                };
                write_json(p, &json)?;
            }
            if !args.quiet {
                print_stdout(&format!(
                    "{} policy, {n} random starts at rest within {START_POSITION} m \
                     (seed {seed}), {steps} steps: {:.0}% reach the reward region, mean time \
                     {}, mean final error {:.1} cm\n",
                    kind.name(),
                    100.0 * report.success_rate,
                    fmt_opt(report.mean_time_to_goal_s),
                    report.mean_final_error_cm,
                ))?;
            }
        }
        classic => {
            let starts = evaluate::lattice(classic, n)?;
            let mc = evaluate::monte_carlo(policy, &starts, steps, kind)?;
            if let Some(p) = &args.json {
                write_json(p, &mc)?;
            }
            if !args.quiet {
                print_stdout(&format!(
                    "{} policy, {} starts ({n} per state variable, over the state bounds), \
                     {steps} steps each: mean discounted return {:.4} (min {:.4}, max {:.4})\n",
                    kind.name(),
                    mc.runs.len(),
                    mc.mean_return,
                    mc.min_return,
                    mc.max_return
                ))?;
            }
        }
    }
    Ok(())
}

/// `--maps`: `V` and the policy's first action component on a 101 x 101 lattice over a 2-D
/// state space.
fn maps(
    policy: &Policy,
    model: &EnvModel,
    path: &std::path::Path,
    kind: PolicyKind,
) -> anyhow::Result<()> {
    const N: usize = 101;
    let Policy::Fqi(p) = policy else {
        anyhow::bail!("--maps draws the value function of a fuzzy Q-iteration policy");
    };
    let spec = model.kind().spec();
    let axis = |d: usize| {
        let (lo, hi) = Dynamics::state_bounds(model, d);
        (0..N)
            .map(|i| lo + (hi - lo) * i as f64 / (N - 1) as f64)
            .collect::<Vec<f64>>()
    };
    let (xs, ys) = (axis(0), axis(1));
    let mut q = vec![0.0; p.n_joint_actions()];
    let mut u = vec![0.0; p.action_dim()];
    let (mut v, mut a) = (Vec::with_capacity(N * N), Vec::with_capacity(N * N));
    for &y in &ys {
        for &x in &xs {
            v.push(p.value(&[x, y])?);
            p.act(kind, &[x, y], &mut q, &mut u)?;
            a.push(u[0]);
        }
    }
    let env = model.kind();
    plot::heat_maps_figure(
        path,
        &format!("{env}: value function and {} policy", kind.name()),
        (spec.state_labels[0], spec.state_labels[1]),
        &[
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
        ],
    )
}
