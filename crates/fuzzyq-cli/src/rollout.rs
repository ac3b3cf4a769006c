//! `fuzzyq rollout`.

use std::fmt::Write as _;
use std::path::PathBuf;

use anyhow::Context;
use clap::{Args, ValueEnum};
use fuzzyq_sim::PolicyArtifact;
use fuzzyq_sim::policy::{AnyPolicy, PolicyKind};
use fuzzyq_sim::rollout::{PAPER_X0, RolloutMetrics, Trajectory, rollout_any};

use crate::{check_writable, plot, write_file, write_json};

#[derive(Args, Debug)]
pub(crate) struct RolloutArgs {
    /// A policy file written by `fuzzyq train`.
    #[arg(long, value_name = "POLICY")]
    policy: PathBuf,
    /// Initial state, comma-separated [default: the paper's -4,-6,-2,2,5,3,2,-1].
    #[arg(long, value_name = "X0", allow_hyphen_values = true)]
    x0: Option<String>,
    /// Steps to simulate (one sample time each).
    #[arg(long, value_name = "K", default_value_t = 75)]
    steps: usize,
    /// Greedy (eq 7) or interpolated (eq 22) policy.
    #[arg(long, value_enum, default_value_t = KindArg::Greedy)]
    policy_kind: KindArg,
    /// Write the trajectory as CSV.
    #[arg(long, value_name = "FILE.csv")]
    csv: Option<PathBuf>,
    /// Draw states and forces over time per agent and the paths in the plane (PNG or SVG).
    #[arg(long, value_name = "FILE.png|FILE.svg")]
    plot: Option<PathBuf>,
    /// Write the metrics as JSON.
    #[arg(long, value_name = "METRICS.json")]
    json: Option<PathBuf>,
    /// Print nothing on success.
    #[arg(long, short)]
    quiet: bool,
}

#[derive(Clone, Copy, Debug, ValueEnum)]
enum KindArg {
    Greedy,
    Interpolated,
}

/// Parses `-4,-6,-2,2` (also with spaces or surrounding brackets).
fn parse_x0(text: &str) -> anyhow::Result<Vec<f64>> {
    let t = text.trim().trim_start_matches('[').trim_end_matches(']');
    t.split(|c: char| c == ',' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .enumerate()
        .map(|(i, s)| {
            s.parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .with_context(|| format!("--x0: value {} ({s:?}) is not a finite number", i + 1))
        })
        .collect()
}

fn csv(t: &Trajectory) -> String {
    let mut out = String::from("t");
    for i in 1..=t.agents {
        for v in ["sx", "sy", "vx", "vy"] {
            let _ = write!(out, ",{v}{i}");
        }
    }
    for i in 1..=t.agents {
        let _ = write!(out, ",ux{i},uy{i}");
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
    if args.steps == 0 {
        anyhow::bail!("--steps must be at least 1");
    }
    let artifact = PolicyArtifact::load(&args.policy)?;
    let agents = match &artifact.config.env {
        fuzzyq_sim::config::EnvConfig::Pointmass(p) => p.agents,
    };
    let x0 = match &args.x0 {
        Some(t) => parse_x0(t)?,
        None if agents == 2 => PAPER_X0.to_vec(),
        None => anyhow::bail!(
            "the policy has {agents} agents; give --x0 with {} values (the default start is the \
             paper's, for 2 agents)",
            4 * agents
        ),
    };
    let kind = match args.policy_kind {
        KindArg::Greedy => PolicyKind::Greedy,
        KindArg::Interpolated => PolicyKind::Interpolated,
    };
    let policy = AnyPolicy::from_artifact(artifact)?;
    let (trajectory, metrics) = rollout_any(&policy, &x0, args.steps, kind)?;
    if let Some(p) = &args.csv {
        write_file(p, csv(&trajectory).as_bytes(), "CSV")?;
    }
    if let Some(p) = &args.plot {
        plot::rollout_figure(p, &trajectory, kind)?;
    }
    if let Some(p) = &args.json {
        write_json(p, &metrics)?;
    }
    if !args.quiet {
        crate::print_stdout(&report(&metrics))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_x0_forms() {
        assert_eq!(parse_x0("-4,-6,2").unwrap(), vec![-4.0, -6.0, 2.0]);
        assert_eq!(parse_x0("[1, 2.5]").unwrap(), vec![1.0, 2.5]);
        assert!(parse_x0("1,x").unwrap_err().to_string().contains("value 2"));
        assert!(parse_x0("1,nan").is_err());
    }
}
