//! `solve_on` with a backend that holds `V` in shards of slab groups and computes every pass
//! from the slab entry points alone (each group fetching only its halo), the way
//! `fuzzyq.distributed` does on Ray: the run equals `solve_from`'s bit for bit, for every
//! scheme, and continued from any sweep's state.

use std::borrow::Cow;
use std::cell::Cell;
use std::ops::{ControlFlow, Range};

use fuzzyq_core::solver::{
    Buf, DiffStats, Grid, Operator, SolveError, SolverConfig, SolverState, Sweeps, diff_stats,
    shift, solve_from, solve_on,
};
use fuzzyq_core::{Backup, Model, Real};
use fuzzyq_tests::medium_two_agent;

/// `V` in groups of slabs, each group its own buffer, as separate machines would hold it.
struct Sharded<'o, 'a, T: Real, M: ?Sized> {
    op: &'o Operator<'a, T, M>,
    groups: Vec<Range<usize>>,
    halos: Vec<Vec<u32>>,
    slab: usize,
    /// `bufs[b][g]`: group `g` of buffer `b`.
    bufs: [Vec<Vec<T>>; 3],
    policy: Vec<Vec<u32>>,
    /// Values moved to the groups' tasks, over the run.
    fetched: Cell<usize>,
}

impl<'o, 'a, T: Real, M: Model<T> + Sync + ?Sized> Sharded<'o, 'a, T, M> {
    fn new(op: &'o Operator<'a, T, M>, per_group: usize) -> Self {
        let layout = op.slab_layout().expect("block path");
        let groups: Vec<Range<usize>> = (0..layout.n_slabs)
            .step_by(per_group)
            .map(|s| s..(s + per_group).min(layout.n_slabs))
            .collect();
        let halos = groups
            .iter()
            .map(|r| op.input_slabs(r.clone()).unwrap())
            .collect();
        let zeros: Vec<Vec<T>> = groups
            .iter()
            .map(|r| vec![T::ZERO; r.len() * layout.slab_len])
            .collect();
        let policy = groups
            .iter()
            .map(|r| vec![0; r.len() * layout.slab_len])
            .collect();
        Self {
            op,
            groups,
            halos,
            slab: layout.slab_len,
            bufs: [zeros.clone(), zeros.clone(), zeros],
            policy,
            fetched: Cell::new(0),
        }
    }

    /// The halo of group `g` gathered from the shards of `b` (through `f` of each value).
    fn halo(&self, g: usize, f: impl Fn(usize, usize) -> T) -> Vec<T> {
        let mut out = Vec::new();
        for &c in &self.halos[g] {
            let c = c as usize;
            let owner = self.groups.iter().position(|r| r.contains(&c)).unwrap();
            let at = (c - self.groups[owner].start) * self.slab;
            out.extend((at..at + self.slab).map(|i| f(owner, i)));
        }
        self.fetched.set(self.fetched.get() + out.len());
        out
    }

    fn of(&self, b: Buf) -> &Vec<Vec<T>> {
        &self.bufs[usize::from(b.0)]
    }

    fn flat<U: Copy>(shards: &[Vec<U>]) -> Vec<U> {
        shards.iter().flatten().copied().collect()
    }

    /// Each group's new shard of `out`, from the halo of `v`.
    fn pass(
        &mut self,
        v: Buf,
        out: Buf,
        mut f: impl FnMut(&Self, usize, &[u32], &[T], &mut [T]) -> Result<(), SolveError>,
    ) -> Result<(), SolveError> {
        let mut fresh = Vec::new();
        for g in 0..self.groups.len() {
            let halo = self.halo(g, |o, i| self.of(v)[o][i]);
            let mut shard = vec![T::ZERO; self.of(out)[g].len()];
            f(self, g, &self.halos[g], &halo, &mut shard)?;
            fresh.push(shard);
        }
        self.bufs[usize::from(out.0)] = fresh;
        Ok(())
    }
}

impl<T: Real, M: Model<T> + Sync + ?Sized> Sweeps<T> for Sharded<'_, '_, T, M> {
    type Error = SolveError;

    fn backup(&mut self, v: Buf, out: Buf) -> Result<(), SolveError> {
        self.pass(v, out, |s, g, halo, vh, o| {
            s.op.apply_slabs(s.groups[g].clone(), halo, vh, o)
        })
    }

    fn backup_greedy(&mut self, v: Buf, out: Buf) -> Result<(), SolveError> {
        let mut policy = std::mem::take(&mut self.policy);
        let r = self.pass(v, out, |s, g, halo, vh, o| {
            s.op.backup_greedy_slabs(s.groups[g].clone(), halo, vh, o, &mut policy[g])
        });
        self.policy = policy;
        r
    }

    fn rewards(&mut self, out: Buf) -> Result<(), SolveError> {
        for g in 0..self.groups.len() {
            let r = self.groups[g].clone();
            self.op
                .reward_slabs(r, &mut self.bufs[usize::from(out.0)][g])?;
        }
        Ok(())
    }

    fn evaluate(&mut self, v: Buf, out: Buf) -> Result<(), SolveError> {
        let policy = std::mem::take(&mut self.policy);
        let r = self.pass(v, out, |s, g, halo, vh, o| {
            s.op.evaluate_slabs(s.groups[g].clone(), halo, vh, &policy[g], o)
        });
        self.policy = policy;
        r
    }

    fn sweep_async(&mut self, _: Buf) -> Result<f64, SolveError> {
        Err(SolveError::Slabs {
            reason: "asynchronous sweeps cannot be sharded",
        })
    }

    fn diff_stats(&mut self, a: Buf, b: Buf, s: T) -> Result<DiffStats, SolveError> {
        Ok((0..self.groups.len())
            .map(|g| diff_stats(&self.of(a)[g], &self.of(b)[g], s))
            .fold(DiffStats::EMPTY, DiffStats::merge))
    }

    fn shift(&mut self, v: Buf, s: T) -> Result<(), SolveError> {
        for shard in &mut self.bufs[usize::from(v.0)] {
            shift(shard, s);
        }
        Ok(())
    }

    fn exact_delta(&mut self, a: Buf, b: Buf) -> Result<f64, SolveError> {
        let mut m = T::ZERO;
        for g in 0..self.groups.len() {
            let dv = self.halo(g, |o, i| self.of(a)[o][i] - self.of(b)[o][i]);
            let x = self
                .op
                .abs_max_slabs(self.groups[g].clone(), &self.halos[g], &dv)?;
            m = m.max_of(x);
        }
        Ok(m.to_f64())
    }

    fn greedy(&mut self, v: Buf) -> Result<(), SolveError> {
        for g in 0..self.groups.len() {
            let halo = self.halo(g, |o, i| self.of(v)[o][i]);
            let mut acts = vec![0; self.policy[g].len()];
            self.op
                .greedy_slabs(self.groups[g].clone(), &self.halos[g], &halo, &mut acts)?;
            self.policy[g] = acts;
        }
        Ok(())
    }

    fn load(&mut self, v: Buf, values: &[T]) -> Result<(), SolveError> {
        let mut rest = values;
        for shard in &mut self.bufs[usize::from(v.0)] {
            let (head, tail) = rest.split_at(shard.len());
            shard.copy_from_slice(head);
            rest = tail;
        }
        Ok(())
    }

    fn load_policy(&mut self, policy: &[u32]) -> Result<(), SolveError> {
        let mut rest = policy;
        for shard in &mut self.policy {
            let (head, tail) = rest.split_at(shard.len());
            shard.copy_from_slice(head);
            rest = tail;
        }
        Ok(())
    }

    fn values(&self, v: Buf) -> Result<Cow<'_, [T]>, SolveError> {
        Ok(Cow::Owned(Self::flat(self.of(v))))
    }

    fn policy(&self) -> Result<Cow<'_, [u32]>, SolveError> {
        Ok(Cow::Owned(Self::flat(&self.policy)))
    }
}

fn bits<T: Real>(x: &[T]) -> Vec<u64> {
    x.iter().map(|y| y.to_f64().to_bits()).collect()
}

/// `solve_from` and `solve_on` over shards of `per_group` slabs agree bit for bit (values,
/// greedy actions, sweep records but their timings), from the start and continued from the
/// state after sweep `k` of the sharded run. Returns the sharded run's values fetched per
/// full broadcast of `V` (per sweep), and its sweep count.
fn agree<T: Real, M: Model<T> + Sync>(
    m: &M,
    g: &Grid<T>,
    config: &SolverConfig,
    per_group: usize,
    k: usize,
) -> (f64, usize) {
    let reference = solve_from(m, g, config, None, |_, _| ControlFlow::Continue(())).unwrap();
    let backup = Backup {
        gamma: T::from_f64(config.gamma),
        absorbing_goal: config.absorbing_goal,
    };
    let op = Operator::new(m, g.view(), backup, config.path).unwrap();
    let mut sharded = Sharded::new(&op, per_group);
    let mut kept: Option<SolverState<'static, T>> = None;
    let got = solve_on(m, g, config, &mut sharded, None, true, |p, s| {
        if p.record.sweep == k {
            kept = s.map(|s| s.clone().into_owned());
        }
        ControlFlow::Continue(())
    })
    .unwrap();
    let same = |a: &fuzzyq_core::solver::Solution<T>, what: &str| {
        let first_diff = |x: &[u64], y: &[u64]| x.iter().zip(y).position(|(a, b)| a != b);
        assert_eq!(
            first_diff(&bits(&a.v), &bits(&reference.v)),
            None,
            "{what}: V"
        );
        assert!(a.greedy == reference.greedy, "{what}: greedy actions");
        assert_eq!(a.sweeps.len(), reference.sweeps.len(), "{what}: sweeps");
        for (x, y) in a.sweeps.iter().zip(&reference.sweeps) {
            assert_eq!(
                (
                    x.delta.lower.to_bits(),
                    x.delta.upper.to_bits(),
                    x.delta_v.to_bits()
                ),
                (
                    y.delta.lower.to_bits(),
                    y.delta.upper.to_bits(),
                    y.delta_v.to_bits()
                ),
                "{what}: sweep {}",
                x.sweep
            );
            assert_eq!(
                (x.extrapolated, x.evaluation),
                (y.extrapolated, y.evaluation)
            );
        }
        assert_eq!(
            a.final_delta.to_bits(),
            reference.final_delta.to_bits(),
            "{what}"
        );
        assert_eq!(
            (a.scheme, a.stop),
            (reference.scheme, reference.stop),
            "{what}"
        );
    };
    same(&got, "sharded");
    let sweeps = got.sweeps.len();
    let per_sweep = sharded.fetched.get() as f64 / (sweeps as f64 * g.n_cores() as f64);
    let state = kept.expect("the run passed sweep k");
    let mut again = Sharded::new(&op, per_group);
    let resumed = solve_on(m, g, config, &mut again, Some(state), false, |_, s| {
        assert!(s.is_none(), "no state shown when not asked");
        ControlFlow::Continue(())
    })
    .unwrap();
    same(&resumed, "resumed");
    (per_sweep, sweeps)
}

#[test]
fn sharded_sweeps_give_the_single_process_run_bit_for_bit() {
    let (m, g) = medium_two_agent::<f32>();
    let plain = SolverConfig {
        max_sweeps: 40,
        ..SolverConfig::default()
    };
    let vi = SolverConfig {
        extrapolate: true,
        ..plain
    };
    let mpi = SolverConfig {
        evaluation_sweeps: 20,
        ..vi
    };
    // Modified policy iteration, value iteration extrapolated and plain, and an absorbing
    // goal (no extrapolation, exact deltas).
    let (fetched, sweeps) = agree(&m, &g, &mpi, 2, 5);
    assert!(sweeps > 6, "a run of several sweeps: {sweeps}");
    // The groups fetch their halos only: a few passes a sweep, each under two copies of V.
    assert!(fetched < 8.0, "{fetched} copies of V fetched per sweep");
    agree(&m, &g, &vi, 3, 4);
    agree(&m, &g, &plain, 1, 7);
    agree(
        &m,
        &g,
        &SolverConfig {
            absorbing_goal: true,
            gamma: 0.9,
            ..plain
        },
        4,
        3,
    );
    let (m, g) = medium_two_agent::<f64>();
    agree(&m, &g, &mpi, 5, 2);
    // From a coarse start: the coarse run in process, its `V` loaded into the shards.
    let (m, g) = fuzzyq_tests::small_one_agent::<f32>();
    assert!(g.coarsened().is_some());
    let coarse = SolverConfig {
        coarse_start: true,
        evaluation_sweeps: 5,
        ..vi
    };
    agree(&m, &g, &coarse, 2, 3);
}
