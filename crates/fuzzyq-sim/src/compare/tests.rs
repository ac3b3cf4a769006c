//! Tests of the comparison: the tiny task, seeds and sweeps, the table, errors.

use super::*;
use crate::io::config::GridConfig;
use crate::model::Dynamics;

/// One agent on a coarse grid: every learner trains in a fraction of a second.
fn tiny() -> CompareConfig {
    let mut task = TrainConfig::default();
    if let EnvConfig::Pointmass(p) = &mut task.env {
        p.agents = 1;
    }
    task.grid = GridConfig {
        position_cores: vec![-6.0, -2.0, -0.5, 0.0, 0.5, 2.0, 6.0],
        velocity_cores: vec![-3.0, 0.0, 3.0],
        heading_divisions: None,
        cores: None,
        membership: Membership::Triangular,
    };
    let mut c = CompareConfig::new(task);
    c.x0 = vec![-4.0, 3.0, 0.0, 0.0];
    c.starts = 5;
    c.steps = 60;
    c.fql.episodes = 40;
    c.vqql.samples = 2000;
    c.vqql_sweep.clear();
    c.batch.samples = 2000;
    c
}

#[test]
fn the_uniform_crisp_grid_has_as_many_cores_evenly_over_each_range() {
    let c = tiny();
    let cores = uniform_cores(&c.task, &c.model().unwrap());
    let p = [-6.0, -4.0, -2.0, 0.0, 2.0, 4.0, 6.0];
    assert_eq!(
        cores,
        vec![
            p.to_vec(),
            p.to_vec(),
            vec![-3.0, 0.0, 3.0],
            vec![-3.0, 0.0, 3.0]
        ]
    );
}

#[test]
fn vqql_gets_as_many_cells_as_the_grid_has_own_state_cores() {
    assert_eq!(CompareConfig::default().vqql.cells, 9 * 9 * 5 * 5);
    assert_eq!(tiny().vqql.cells, 7 * 7 * 3 * 3);
}

#[test]
fn every_learner_from_samples_gets_the_budget() {
    let c = tiny();
    let l = with_budget(&c, Learner::LearnedModel, 1234);
    assert_eq!(l.model_learning.collection.samples, 1234);
    let f = with_budget(&c, Learner::Fql, 3000);
    assert_eq!(f.fql.episodes * f.fql.max_steps, 3000);
    assert_eq!(
        f.fql.eval_every, 0,
        "no evaluation episodes beyond the budget"
    );
    let v = with_budget(&c, Learner::Vqql, 3000);
    assert_eq!(v.vqql.samples + v.fql.episodes * v.fql.max_steps, 3000);
    assert_eq!(with_budget(&c, Learner::Vqql, 100).vqql.cells, 25);
    let b = with_budget(&c, Learner::VqqlBatch, 700);
    assert_eq!(b.batch.samples, 700);
    assert_eq!(with_budget(&c, Learner::FqiSamples, 700), b);
    assert_eq!(with_budget(&c, Learner::Fqi, 100), c);
}

#[test]
fn sample_efficiency_is_seeded_and_skips_the_learners_of_the_model() {
    let mut c = tiny();
    c.learners = vec![Learner::Fqi, Learner::LearnedModel, Learner::Fql];
    let mut seen = Vec::new();
    let strip = |mut p: Vec<EfficiencyPoint>| {
        for q in &mut p {
            q.train_seconds = 0.0;
        }
        p
    };
    let a = strip(sample_efficiency(&c, &[300, 3000], |l, n| seen.push((l, n))).unwrap());
    assert_eq!(
        seen,
        [
            (Learner::LearnedModel, 300),
            (Learner::LearnedModel, 3000),
            (Learner::Fql, 300),
            (Learner::Fql, 3000)
        ]
    );
    assert_eq!(
        a,
        strip(sample_efficiency(&c, &[300, 3000], |_, _| {}).unwrap())
    );
    // 3,000 transitions pin down the one point mass's model: fuzzy Q-iteration's result.
    let fqi = compare(
        &CompareConfig {
            learners: vec![Learner::Fqi],
            ..c.clone()
        },
        |_| {},
    )
    .unwrap();
    assert_eq!(a[1].success_rate, fqi.reports[0].success_rate);
    assert!(sample_efficiency(&c, &[0], |_, _| {}).is_err());
    // Two transitions cannot show every block action: no model, reported, not an error.
    c.learners = vec![Learner::LearnedModel];
    let few = sample_efficiency(&c, &[2], |_, _| {}).unwrap();
    assert_eq!(few[0].success_rate, 0.0);
    assert!(
        few[0].failure.as_deref().unwrap().contains("collect more"),
        "{few:?}"
    );
}

/// How many `(position, velocity)` cores of one axis of a one-agent point mass reach the
/// origin's core when every successor goes to its nearest core (ties to the upper one).
fn reaching_origin(model: &PointMass, pos: &[f64], vel: &[f64]) -> usize {
    let nearest = |c: &[f64], x: f64| {
        (0..c.len())
            .min_by(|&i, &j| {
                (c[i] - x)
                    .abs()
                    .total_cmp(&(c[j] - x).abs())
                    .then(j.cmp(&i))
            })
            .unwrap()
    };
    let forces = &model.config().force_levels;
    let succ: Vec<Vec<(usize, usize)>> = (0..pos.len() * vel.len())
        .map(|k| {
            let (p, v) = (pos[k / vel.len()], vel[k % vel.len()]);
            forces
                .iter()
                .map(|&f| {
                    let mut next = [0.0; 4];
                    Dynamics::step(model, &[p, 0.0, v, 0.0], &[f, 0.0], &mut next);
                    (nearest(pos, next[0]), nearest(vel, next[2]))
                })
                .collect()
        })
        .collect();
    let origin = (nearest(pos, 0.0), nearest(vel, 0.0));
    let mut reach = vec![false; succ.len()];
    reach[origin.0 * vel.len() + origin.1] = true;
    loop {
        let before = reach.iter().filter(|&&r| r).count();
        for k in 0..succ.len() {
            if succ[k].iter().any(|&(i, j)| reach[i * vel.len() + j]) {
                reach[k] = true;
            }
        }
        let after = reach.iter().filter(|&&r| r).count();
        if after == before {
            return after;
        }
    }
}

#[test]
fn same_configuration_same_table() {
    let c = tiny();
    let strip = |mut c: Comparison| {
        for r in &mut c.reports {
            r.train_seconds = 0.0;
        }
        c
    };
    let mut events = Vec::new();
    let a = strip(compare(&c, |e| events.push(e)).unwrap());
    let b = strip(compare(&c, |_| {}).unwrap());
    assert_eq!(a, b);
    assert_eq!(
        a.reports.len(),
        <Learner as fuzzyq_core::NamedOption>::ALL.len()
    );
    assert_eq!(
        events.len(),
        3 * <Learner as fuzzyq_core::NamedOption>::ALL.len()
    );
    assert_eq!(events[0], Event::Training(Learner::Fqi));
    // The model-based learners represent cores x actions; the crisp one is a different
    // learner on the same cores.
    let (fqi, crisp) = (&a.reports[0], &a.reports[1]);
    assert_eq!(fqi.parameters, 441 * 25);
    assert_eq!(crisp.parameters, fqi.parameters);
    assert_eq!(fqi.iteration_unit, "sweeps");
    assert_eq!(a.reports[2].parameters, fqi.parameters);
    // The count of cores that never reach the reward, against an independent count: each
    // axis of the one agent is a crisp graph on its 21 cores, the reward needs both axes
    // at the origin's core, and the origin with no force stays there.
    assert!(
        fqi.notes.is_empty(),
        "every fuzzy core reaches it: {:?}",
        fqi.notes
    );
    let model = c.model().unwrap();
    for (report, learner) in [
        (crisp, Learner::Crisp),
        (&a.reports[2], Learner::CrispUniform),
    ] {
        let cores = match learner {
            Learner::Crisp => c.task.grid_cores(),
            _ => uniform_cores(&c.task, &model),
        };
        let r = reaching_origin(&model, &cores[0], &cores[2]);
        let stuck = 441 - r * r;
        let note = format!("V takes its lowest value at {stuck} of 441 cores");
        assert!(
            report.notes[0].starts_with(&note),
            "{note}: {:?}",
            report.notes
        );
    }
    assert_eq!(a.reports[3].iteration_unit, "episodes");
    assert_eq!(a.reports[3].iterations, 40);
    assert_eq!(a.reports[5].parameters, 441 * 25);
    // The batch learners: fuzzy cores and VQQL's cells, fitted on the same transitions.
    for (k, cells) in [(7, 7 * 7 * 3 * 3), (8, 441)] {
        let r = &a.reports[k];
        assert_eq!(r.iteration_unit, "iterations", "{}", r.learner.name());
        assert_eq!(r.parameters, cells * 25);
        assert!(r.converged && r.largest_parameter.unwrap() <= 5.0 / (1.0 - 0.96));
    }
    // The table has one column per learner and the paper's two.
    let md = a.to_markdown();
    let header = md.lines().next().unwrap();
    assert_eq!(
        header.matches('|').count(),
        <Learner as fuzzyq_core::NamedOption>::ALL.len() + 4
    );
    assert_eq!(
        a.to_csv().lines().count(),
        1 + <Learner as fuzzyq_core::NamedOption>::ALL.len()
    );
}

#[test]
fn the_bootstrap_interval_holds_the_mean_and_is_seeded() {
    assert_eq!(bootstrap(&[], 1), None);
    let one = bootstrap(&[3.5], 1).unwrap();
    assert_eq!((one.mean, one.lo, one.hi), (3.5, 3.5, 3.5));
    let v = [1.0, 4.0, 2.0, 8.0, 5.0];
    let e = bootstrap(&v, 9).unwrap();
    assert_eq!(e.mean, 4.0);
    assert!(e.lo < e.mean && e.mean < e.hi, "{e:?}");
    assert!(e.lo >= 1.0 && e.hi <= 8.0, "{e:?}");
    assert_eq!(bootstrap(&v, 9), Some(e));
    // A constant sample has no spread.
    let c = bootstrap(&[2.0; 5], 9).unwrap();
    assert_eq!((c.lo, c.hi), (2.0, 2.0));
}

#[test]
fn seeds_and_the_codebook_sweep_are_reported_whole() {
    let mut c = tiny();
    c.learners = vec![Learner::Fql, Learner::Vqql];
    c.seeds = 3;
    c.vqql_sweep = vec![8, 32];
    c.set_reward(RewardShape::Shaped);
    let mut runs = Vec::new();
    let a = compare(&c, |e| {
        if let Event::Run {
            learner,
            seed,
            cells,
        } = e
        {
            runs.push((learner, seed, cells));
        }
    })
    .unwrap();
    let base = c.fql.seed;
    assert_eq!(runs.len(), 3 + 2 * 3);
    assert_eq!(runs[0], (Learner::Fql, base, None));
    assert_eq!(runs[3], (Learner::Vqql, base, Some(8)));
    assert_eq!(runs[8], (Learner::Vqql, base + 2, Some(32)));
    assert_eq!(a.reward, RewardShape::Shaped);
    // Every learner from samples: three seeds, the means over them, every path.
    for (k, r) in a.reports.iter().enumerate() {
        let o = r.over_seeds.as_ref().unwrap();
        assert_eq!(o.seeds, [base, base + 1, base + 2]);
        let mean = o.final_error_cm.iter().sum::<f64>() / 3.0;
        assert!((r.final_error_cm - mean).abs() < 1e-9);
        assert!(o.final_error.lo <= mean && mean <= o.final_error.hi);
        assert_eq!(a.seed_trajectories[k].len(), 2);
        assert!(r.largest_parameter.unwrap() > 0.0);
    }
    // The sweep: both sizes, one best, and the VQQL column is the best size's.
    assert_eq!(a.vqql_sweep.len(), 2);
    let best: Vec<&SweepPoint> = a.vqql_sweep.iter().filter(|p| p.best).collect();
    assert_eq!(best.len(), 1);
    let other = a.vqql_sweep.iter().find(|p| !p.best).unwrap();
    let key = |p: &SweepPoint| {
        (
            p.over_seeds.success.mean,
            -p.over_seeds.mean_final_error.mean,
        )
    };
    assert!(key(best[0]) >= key(other));
    assert_eq!(a.reports[1].parameters, best[0].parameters);
    assert_eq!(a.reports[1].over_seeds.as_ref(), Some(&best[0].over_seeds));
    // A different seed is a different run (the seeds are really used).
    let o = a.reports[0].over_seeds.as_ref().unwrap();
    assert!(
        o.final_error_cm.windows(2).any(|w| w[0] != w[1])
            || o.mean_final_error_cm.windows(2).any(|w| w[0] != w[1])
    );
    let md = a.to_markdown();
    assert!(
        md.contains("VQQL codebook sweep") && md.contains("Reward: shaped"),
        "{md}"
    );
    assert_eq!(a.to_csv().lines().nth(1).unwrap().split(',').count(), 20);
    // Seeded: the same configuration, the same table.
    let strip = |mut c: Comparison| {
        for r in &mut c.reports {
            r.train_seconds = 0.0;
        }
        c
    };
    assert_eq!(strip(a), strip(compare(&c, |_| {}).unwrap()));
    c.seeds = 0;
    assert!(
        compare(&c, |_| {})
            .unwrap_err()
            .to_string()
            .contains("seeds")
    );
}

#[test]
fn the_default_sweep_doubles_up_to_the_cores() {
    assert_eq!(default_sweep(2025), [16, 32, 64, 128, 256, 512, 1024, 2025]);
    assert_eq!(default_sweep(16), [16]);
    assert_eq!(default_sweep(5), [5]);
    assert_eq!(CompareConfig::default().vqql_sweep.last(), Some(&2025));
}

#[test]
fn bad_configurations_name_the_field() {
    let check = |c: CompareConfig, needle: &str| {
        let e = compare(&c, |_| {}).unwrap_err().to_string();
        assert!(e.contains(needle), "{e} does not mention {needle}");
    };
    let mut c = tiny();
    c.learners = vec![Learner::Fqi, Learner::Fqi];
    check(c, "fqi is named twice");
    let mut c = tiny();
    c.learners.clear();
    check(c, "learners");
    let mut c = tiny();
    c.x0 = vec![0.0; 3];
    check(c, "x0");
    let mut c = tiny();
    c.start_position = f64::NAN;
    check(c, "start_position");
    let mut c = tiny();
    c.steps = 0;
    check(c, "steps");
    let mut c = tiny();
    c.task = TrainConfig::default_for(crate::model::EnvKind::Khepera).unwrap();
    check(c, "point-mass task");
    assert!(
        Learner::parse("cmommt")
            .unwrap_err()
            .to_string()
            .contains("fql-literal")
    );
    for l in <Learner as fuzzyq_core::NamedOption>::ALL {
        assert_eq!(Learner::parse(l.name()).unwrap(), *l);
    }
}
