//! What each iteration scheme's driver asks of a [`Sweeps`] backend: only the value buffers
//! [`Scheme::value_buffers`] names, and the exact delta only where
//! [`Scheme::uses_exact_delta`] says. A GPU run holds just those buffers (three point masses on
//! the paper's cores fit one H200 under modified policy iteration because it holds `V` twice),
//! so a driver that asked for more would make a run fail, or allocate, mid-way. And a coarse
//! start, which `solve_with` solves on another thread beside the run's preparation,
//! gives the run the CPU's bits.

use std::borrow::Cow;
use std::collections::BTreeSet;
use std::ops::ControlFlow;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use fuzzyq_core::solver::{self, Buf, DiffStats, Scheme, Sweeps};
use fuzzyq_gpu::reference::{HostSweeps, Rounding};
use fuzzyq_sim::io::config::TrainConfig;
use fuzzyq_sim::model::EnvKind;

/// What one backend was asked for.
#[derive(Debug, Default)]
struct Asked {
    bufs: BTreeSet<u8>,
    exact_delta: bool,
}

/// A backend that passes every call to `inner` and notes the buffers and passes asked for.
struct Recording<S> {
    inner: S,
    asked: Arc<Mutex<Asked>>,
}

impl<S> Recording<S> {
    fn saw(&self, bufs: &[Buf]) {
        self.asked
            .lock()
            .unwrap()
            .bufs
            .extend(bufs.iter().map(|b| b.0));
    }
}

impl<S: Sweeps<f32>> Sweeps<f32> for Recording<S> {
    type Error = S::Error;

    fn backup(&mut self, v: Buf, out: Buf) -> Result<(), S::Error> {
        self.saw(&[v, out]);
        self.inner.backup(v, out)
    }
    fn backup_greedy(&mut self, v: Buf, out: Buf) -> Result<(), S::Error> {
        self.saw(&[v, out]);
        self.inner.backup_greedy(v, out)
    }
    fn rewards(&mut self, out: Buf) -> Result<(), S::Error> {
        self.saw(&[out]);
        self.inner.rewards(out)
    }
    fn evaluate(&mut self, v: Buf, out: Buf) -> Result<(), S::Error> {
        self.saw(&[v, out]);
        self.inner.evaluate(v, out)
    }
    fn sweep_async(&mut self, v: Buf) -> Result<f64, S::Error> {
        self.saw(&[v]);
        self.inner.sweep_async(v)
    }
    fn diff_stats(&mut self, a: Buf, b: Buf, s: f32) -> Result<DiffStats, S::Error> {
        self.saw(&[a, b]);
        self.inner.diff_stats(a, b, s)
    }
    fn shift(&mut self, v: Buf, s: f32) -> Result<(), S::Error> {
        self.saw(&[v]);
        self.inner.shift(v, s)
    }
    fn exact_delta(&mut self, a: Buf, b: Buf) -> Result<f64, S::Error> {
        self.saw(&[a, b]);
        self.asked.lock().unwrap().exact_delta = true;
        self.inner.exact_delta(a, b)
    }
    fn greedy(&mut self, v: Buf) -> Result<(), S::Error> {
        self.saw(&[v]);
        self.inner.greedy(v)
    }
    fn load(&mut self, v: Buf, values: &[f32]) -> Result<(), S::Error> {
        self.saw(&[v]);
        self.inner.load(v, values)
    }
    fn load_policy(&mut self, policy: &[u32]) -> Result<(), S::Error> {
        self.inner.load_policy(policy)
    }
    fn values(&self, v: Buf) -> Result<Cow<'_, [f32]>, S::Error> {
        self.saw(&[v]);
        self.inner.values(v)
    }
    fn policy(&self) -> Result<Cow<'_, [u32]>, S::Error> {
        self.inner.policy()
    }
}

/// Every backend a run of `c` makes (its coarse start's too): its scheme and what it was
/// asked for.
fn asked_of(c: &TrainConfig) -> Vec<(Scheme, Arc<Mutex<Asked>>)> {
    let model = c.build_model().unwrap();
    let grid = c.grid::<f32>().unwrap();
    let config = c.solver.solver_config();
    let mut made = Vec::new();
    solver::solve_with(
        &model,
        &grid,
        &config,
        None,
        true,
        &mut |op, scheme| {
            let asked = Arc::new(Mutex::new(Asked::default()));
            made.push((scheme, asked.clone()));
            let inner = HostSweeps::new(op, Rounding::Fused)?;
            Ok(Recording { inner, asked })
        },
        |_, _| ControlFlow::Continue(()),
    )
    .unwrap();
    made
}

#[test]
fn each_scheme_asks_only_for_the_buffers_it_names() {
    let mut pointmass = TrainConfig::default_for(EnvKind::Pointmass).unwrap();
    pointmass.grid.position_cores = vec![-6.0, -0.5, 0.0, 0.5, 6.0];
    pointmass.grid.velocity_cores = vec![-3.0, 0.0, 3.0];
    // Value iteration without extrapolation, to the exact stopping rule.
    let mut value = pointmass.clone();
    value.solver.extrapolate = false;
    value.solver.evaluation_sweeps = 0;
    value.solver.max_sweeps = 40;
    let mut seen = BTreeSet::new();
    for c in [
        pointmass,
        value,
        TrainConfig::default_for(EnvKind::Dcmotor).unwrap(),
    ] {
        for (scheme, asked) in asked_of(&c) {
            let asked = asked.lock().unwrap();
            let buffers = scheme.value_buffers();
            assert!(
                asked.bufs.iter().all(|&b| b < buffers),
                "{scheme:?}: {asked:?}"
            );
            assert!(
                !asked.exact_delta || scheme.uses_exact_delta(),
                "{scheme:?}"
            );
            // Each scheme uses all it names: value iteration's exact rule ran here.
            assert_eq!(
                asked.bufs.len(),
                usize::from(buffers),
                "{scheme:?}: {asked:?}"
            );
            seen.insert(format!("{scheme:?} {}", asked.exact_delta));
        }
    }
    let seen: Vec<_> = seen.into_iter().collect();
    assert_eq!(seen, ["ModifiedPolicy false", "Value true"]);
}

/// `solve_with` solves a fresh run's coarse start on another thread while it prepares the
/// run's operator: the point masses take it and give the bits of the CPU's run, which solves
/// it first. The DC motor's reward depends on the action, so its operator cannot evaluate a
/// policy and takes no coarse start: the coarse solve begun beside its preparation is dropped,
/// and the run starts from `V = 0` as on the CPU.
#[test]
fn a_coarse_start_beside_the_set_up_gives_the_cpu_bits() {
    let mut pointmass = TrainConfig::default_for(EnvKind::Pointmass).unwrap();
    pointmass.grid.position_cores = vec![-6.0, -2.0, -0.5, 0.0, 0.5, 2.0, 6.0];
    pointmass.grid.velocity_cores = vec![-3.0, 0.0, 3.0];
    pointmass.solver.coarse_start = true;
    let mut dcmotor = TrainConfig::default_for(EnvKind::Dcmotor).unwrap();
    dcmotor.solver.extrapolate = true;
    dcmotor.solver.evaluation_sweeps = 5;
    dcmotor.solver.coarse_start = true;
    for (c, takes) in [(pointmass, true), (dcmotor, false)] {
        let model = c.build_model().unwrap();
        let grid = c.grid::<f32>().unwrap();
        let config = c.solver.solver_config();
        let made = AtomicUsize::new(0);
        let beside = solver::solve_with(
            &model,
            &grid,
            &config,
            None,
            false,
            &mut |op, _| {
                made.fetch_add(1, Ordering::Relaxed);
                HostSweeps::new(op, Rounding::Fused)
            },
            |_, _| ControlFlow::Continue(()),
        )
        .unwrap();
        let cpu = solver::solve(&model, &grid, &config, |_| ControlFlow::Continue(())).unwrap();
        let what = format!("{:?}", c.env.kind());
        // The coarse start's backend and the run's.
        assert_eq!(made.into_inner(), 2, "{what}");
        let coarse = |s: &solver::Solution<f32>| s.coarse.map(|c| (c.cores, c.sweeps));
        assert_eq!(coarse(&beside).is_some(), takes, "{what}");
        assert_eq!(coarse(&beside), coarse(&cpu), "{what}");
        assert_eq!(beside.sweeps.len(), cpu.sweeps.len(), "{what}");
        fuzzyq_tests::assert_same_bits(&[cpu, beside]);
    }
}
