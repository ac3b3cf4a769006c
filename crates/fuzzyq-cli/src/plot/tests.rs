//! The figures render to PNG and SVG from made-up runs, and refuse bad input.

use std::path::Path;

use fuzzyq_core::q::PolicyKind;
use fuzzyq_sim::learn::fql::EpisodeRecord;
use fuzzyq_sim::model::arena::{Arena, Obstacle};
use fuzzyq_sim::run::metrics::KheperaRun;
use fuzzyq_sim::run::metrics::Trajectory;

use super::{khepera_figure, learning_curve_figure, success_figure};

/// Two robots spiralling in towards the origin; robot 2's heading crosses +-pi.
fn khepera_run(steps: usize) -> KheperaRun {
    let dt = 0.25;
    let starts = [(-4.0_f64, 5.0_f64), (5.0, 3.0)];
    let poses: Vec<Vec<[f64; 3]>> = (0..=steps)
        .map(|k| {
            let s = k as f64 / steps.max(1) as f64;
            starts
                .iter()
                .enumerate()
                .map(|(i, &(x0, y0))| {
                    let r = (x0.hypot(y0)) * (1.0 - 0.97 * s);
                    let a = y0.atan2(x0) + (1.0 + i as f64) * 2.5 * s;
                    let (x, y) = (r * a.cos(), r * a.sin());
                    let heading = fuzzyq_sim::model::khepera::wrap_heading(a + 2.0 + 3.0 * s);
                    [x, y, heading]
                })
                .collect()
        })
        .collect();
    let states: Vec<Vec<f64>> = (0..=steps)
        .map(|k| {
            (0..2)
                .flat_map(|i| {
                    let p = poses[k][i];
                    let q = if k == 0 { p } else { poses[k - 1][i] };
                    [p[0], p[1], (p[0] - q[0]) / dt, (p[1] - q[1]) / dt]
                })
                .collect()
        })
        .collect();
    let action_indices: Vec<Vec<usize>> = (0..steps)
        .map(|k| vec![(k / 5) % 4, (k / 3 + 1) % 4])
        .collect();
    let actions = action_indices
        .iter()
        .map(|a| a.iter().flat_map(|&i| [0.1 * i as f64, -0.1]).collect())
        .collect();
    let rewards = (0..steps)
        .map(|k| if k + 5 >= steps { 1.0 } else { 0.0 })
        .collect();
    KheperaRun {
        trajectory: Trajectory {
            dt,
            agents: 2,
            states,
            actions,
            rewards,
        },
        poses,
        action_indices,
        sonar: vec![vec![vec![1.0; 8]; 2]; steps + 1],
    }
}

fn arena() -> Arena {
    Arena {
        x: [-6.0, 6.0],
        y: [-6.0, 6.0],
        obstacles: vec![
            Obstacle::Box {
                center: [-2.0, 2.5],
                half_extents: [0.6, 0.05],
                angle_deg: 38.66,
            },
            Obstacle::Disc {
                center: [2.0, -2.0],
                radius: 0.3,
            },
        ],
    }
}

fn curve(episodes: usize) -> Vec<EpisodeRecord> {
    (0..episodes)
        .map(|e| {
            let s = e as f64 / episodes as f64;
            let noise = ((e * 7919) % 13) as f64 / 13.0 - 0.5;
            EpisodeRecord {
                episode: e,
                steps: 200 - (150.0 * s) as usize,
                ret: -20.0 + 25.0 * s + 6.0 * noise,
                discounted_return: -10.0 + 12.0 * s,
                mean_abs_td: if e % 17 == 3 {
                    f64::NAN
                } else {
                    1.0 - 0.8 * s + 0.1 * noise
                },
                max_abs_td: 2.0,
                epsilon: 0.3 * (1.0 - s) + 0.05,
                alpha: 0.5 / (1.0 + 0.01 * e as f64),
                param_change: match e {
                    e if e < 10 => f64::NAN,
                    e if e + 10 >= episodes => 0.0,
                    e => 2.0 * (-(e as f64) / 40.0).exp(),
                },
                terminal: e % 3 == 0,
                eval_mean_return: (e % 25 == 24).then_some(-15.0 + 25.0 * s),
                eval_success_rate: (e % 25 == 24).then_some(s.min(1.0)),
            }
        })
        .collect()
}

fn starts(count: usize) -> (Vec<Vec<[f64; 3]>>, Vec<bool>) {
    let starts: Vec<Vec<[f64; 3]>> = (0..count)
        .map(|k| {
            let a = k as f64 * 2.399;
            let r = 1.0 + (k % 5) as f64;
            vec![
                [r * a.cos(), r * a.sin(), 0.0],
                [r * a.cos() + 0.8, r * a.sin() - 0.5, 1.0],
            ]
        })
        .collect();
    let ok = (0..count).map(|k| k % 3 != 0).collect();
    (starts, ok)
}

/// Renders with `draw` to PNG and SVG in a fresh directory and checks the files.
fn renders(draw: impl Fn(&Path) -> anyhow::Result<()>) {
    let dir = tempfile::tempdir().unwrap();
    for ext in ["png", "svg"] {
        let path = dir.path().join(format!("fig.{ext}"));
        draw(&path).unwrap();
        crate::output::commit().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(bytes.len() > 10_000, "{ext}: only {} bytes", bytes.len());
        if ext == "png" {
            assert_eq!(&bytes[1..4], b"PNG");
        } else {
            assert!(String::from_utf8_lossy(&bytes).contains("<svg"));
        }
    }
    // Nothing but the figures: the temporary files were renamed away.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
}

#[test]
fn khepera_figure_renders() {
    let run = khepera_run(80);
    renders(|p| khepera_figure(p, &run, &arena(), 0.07, PolicyKind::Greedy, "test run"));
    // One robot, no obstacles, no steps.
    let mut one = khepera_run(0);
    one.trajectory.agents = 1;
    for x in &mut one.trajectory.states {
        x.truncate(4);
    }
    for p in &mut one.poses {
        p.truncate(1);
    }
    renders(|p| {
        khepera_figure(
            p,
            &one,
            &Arena::default(),
            0.07,
            PolicyKind::Interpolated,
            "one robot",
        )
    });
}

#[test]
fn khepera_figure_refuses_bad_runs() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fig.png");
    let mut empty = khepera_run(10);
    empty.trajectory.states.clear();
    empty.poses.clear();
    let k = PolicyKind::Greedy;
    assert!(khepera_figure(&path, &empty, &arena(), 0.07, k, "").is_err());
    let mut short = khepera_run(10);
    short.action_indices.pop();
    assert!(khepera_figure(&path, &short, &arena(), 0.07, k, "").is_err());
    let run = khepera_run(10);
    assert!(khepera_figure(&path, &run, &arena(), 0.0, k, "").is_err());
    let pdf = dir.path().join("fig.pdf");
    assert!(khepera_figure(&pdf, &run, &arena(), 0.07, k, "").is_err());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

#[test]
fn learning_curve_figure_renders() {
    let c = curve(300);
    renders(|p| learning_curve_figure(p, &c, "learning curve"));
    // No evaluations, no full window, a single episode.
    let mut bare = curve(1);
    bare[0].eval_mean_return = None;
    bare[0].eval_success_rate = None;
    bare[0].param_change = f64::NAN;
    bare[0].mean_abs_td = f64::NAN;
    renders(|p| learning_curve_figure(p, &bare, "one episode"));
    let dir = tempfile::tempdir().unwrap();
    assert!(learning_curve_figure(&dir.path().join("fig.svg"), &[], "").is_err());
}

#[test]
fn success_figure_renders() {
    let (s, ok) = starts(60);
    renders(|p| success_figure(p, &s, &ok, &arena(), "40 of 60 random starts succeed"));
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fig.png");
    assert!(success_figure(&path, &[], &[], &arena(), "").is_err());
    assert!(success_figure(&path, &s, &ok[1..], &arena(), "").is_err());
    assert!(success_figure(&path, &[vec![]], &[true], &arena(), "").is_err());
}

#[test]
#[ignore = "writes /tmp/fig-*.png for a look"]
fn write_examples() {
    let run = khepera_run(80);
    khepera_figure(
        Path::new("/tmp/fig-khepera.png"),
        &run,
        &arena(),
        0.07,
        PolicyKind::Greedy,
        "Khepera IV robots, greedy policy on the rapier plant: both arrive, no collision",
    )
    .unwrap();
    learning_curve_figure(
        Path::new("/tmp/fig-learning.png"),
        &curve(300),
        "Fuzzy Q-learning on the Khepera model",
    )
    .unwrap();
    let (s, ok) = starts(60);
    success_figure(
        Path::new("/tmp/fig-success.png"),
        &s,
        &ok,
        &arena(),
        "greedy policy: 40 of 60 random starts succeed (seed 1)",
    )
    .unwrap();
    crate::output::commit().unwrap();
}
