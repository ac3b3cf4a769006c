//! The GPU's passes on the host, in the GPU's order, with fused or rounded products: the
//! reference an adapter is checked against.
//!
//! [`HostSweeps`] computes every pass as [`GpuSweeps`](crate::GpuSweeps) does, one plain loop
//! at a time: the stages of a slab in full, each element a chain over its row's entries in
//! order from 0, then each core's reduction over the joint actions as the CPU's reduction
//! does. With [`Rounding::Fused`] the chains are fused multiply-adds and the results are the
//! CPU kernels' bits (a test checks it); with [`Rounding::Product`] each product is rounded
//! before it is added, which is what an adapter whose `fma` is not fused computes (Mesa's
//! lavapipe, the software Vulkan that CI runs the GPU path on).

use std::borrow::Cow;

use fuzzyq_core::Model;
use fuzzyq_core::solver::{Buf, DiffStats, Operator, SolveError, Sweeps};

/// How a chain of multiply-adds rounds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Rounding {
    /// `fma(w, x, acc)` in one rounding (the CPU kernels; NVIDIA's GPUs).
    Fused,
    /// `w * x` rounded, then added (an adapter that does not fuse, such as lavapipe).
    Product,
}

impl Rounding {
    /// `acc[i] = w * x[i] + acc[i]` for every `i`, rounded as `self` says.
    fn chain(self, w: f32, x: &[f32], acc: &mut [f32]) {
        match self {
            Rounding::Fused => fused_chain(w, x, acc),
            Rounding::Product => {
                for (a, &x) in acc.iter_mut().zip(x) {
                    *a += w * x;
                }
            }
        }
    }
}

/// [`Rounding::Fused`]'s step: `f32::mul_add`, one instruction where the CPU has FMA (else
/// the library's correctly rounded `fmaf`, the same bits, many times slower).
fn fused_chain(w: f32, x: &[f32], acc: &mut [f32]) {
    #[inline(always)]
    fn body(w: f32, x: &[f32], acc: &mut [f32]) {
        for (a, &x) in acc.iter_mut().zip(x) {
            *a = w.mul_add(x, *a);
        }
    }
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("fma") {
        #[target_feature(enable = "fma")]
        fn with_fma(w: f32, x: &[f32], acc: &mut [f32]) {
            body(w, x, acc)
        }
        // SAFETY: the CPU has FMA (checked above), the only feature `with_fma` enables.
        #[allow(unsafe_code)]
        unsafe {
            with_fma(w, x, acc)
        };
        return;
    }
    body(w, x, acc)
}

/// One table, owned.
#[derive(Clone, Debug)]
struct Table {
    n_cores: usize,
    n_actions: usize,
    r_len: usize,
    p_len: usize,
    ptr: Vec<u32>,
    col: Vec<u32>,
    weight: Vec<f32>,
}

/// The passes of a run on the host, as the GPU computes them ([module docs](self)).
#[derive(Clone, Debug)]
pub struct HostSweeps {
    rounding: Rounding,
    tables: Vec<Table>,
    map: Option<Vec<u32>>,
    n_joint: usize,
    gamma: f32,
    rewards: Option<Vec<f32>>,
    reward_table: Vec<f32>,
    goal: Vec<bool>,
    can_evaluate: bool,
    n: usize,
    bufs: [Vec<f32>; 3],
    policy: Vec<u32>,
}

impl HostSweeps {
    /// The passes of `op` (block path, no terminal states) with products rounded as
    /// `rounding` says.
    pub fn new<M: Model<f32> + Sync + ?Sized>(
        op: &Operator<'_, f32, M>,
        rounding: Rounding,
    ) -> Result<Self, SolveError> {
        let plan = op.block_plan().ok_or(SolveError::NoBlocks)?;
        assert!(!plan.terminals, "the GPU path refuses terminal states");
        let n = op.n_cores();
        let tables = plan
            .tables
            .iter()
            .map(|t| Table {
                n_cores: t.n_cores,
                n_actions: t.n_actions,
                r_len: t.r_len,
                p_len: t.p_len,
                ptr: t.ptr.to_vec(),
                col: t.col.to_vec(),
                weight: t.weight.to_vec(),
            })
            .collect();
        Ok(Self {
            rounding,
            tables,
            map: plan.joint_to_product.map(<[u32]>::to_vec),
            n_joint: plan.n_joint,
            gamma: plan.gamma,
            rewards: plan.rewards.map(<[f32]>::to_vec),
            reward_table: if plan.rewards.is_some() {
                Vec::new()
            } else {
                op.reward_rows()
            },
            goal: plan.goal.to_vec(),
            can_evaluate: plan.can_evaluate,
            n,
            bufs: [vec![0.0; n], vec![0.0; n], vec![0.0; n]],
            policy: vec![0; n],
        })
    }

    /// Every core's expected values under `v`, a row of product actions per core, given to
    /// `each(core, row)` in order of the cores: the stages of each slab in turn. Each element
    /// is its row's chain over the entries in order from `0.0`; the loops run an entry at a
    /// time over a row's contiguous elements, which sums every element in the same order as
    /// one element at a time would.
    fn expected(&self, v: &[f32], mut each: impl FnMut(usize, &[f32])) {
        let nb = self.tables.len();
        let last = &self.tables[nb - 1];
        let width = last.p_len * last.n_actions;
        let slab = self.tables[0].r_len;
        let (mut input, mut next) = (Vec::new(), Vec::new());
        for c0 in 0..self.tables[0].n_cores {
            // The slab's tensor through the stages: `[prefix][r][a][p]`.
            let mut prefixes = 1usize;
            for (b, t) in self.tables.iter().enumerate() {
                let (r_len, p_len, na) = (t.r_len, t.p_len, t.n_actions);
                let cores = if b == 0 { c0..c0 + 1 } else { 0..t.n_cores };
                let src: &[f32] = if b == 0 { v } else { &input };
                next.clear();
                next.resize(prefixes * cores.len() * r_len * na * p_len, 0.0f32);
                for q in 0..prefixes {
                    let base = if b == 0 { 0 } else { q * t.n_cores };
                    for (ci, c) in cores.clone().enumerate() {
                        let oq = q * cores.len() + ci;
                        for a in 0..na {
                            let row = c * na + a;
                            for e in t.ptr[row] as usize..t.ptr[row + 1] as usize {
                                let x0 = (base + t.col[e] as usize) * r_len * p_len;
                                for r in 0..r_len {
                                    let o = ((oq * r_len + r) * na + a) * p_len;
                                    self.rounding.chain(
                                        t.weight[e],
                                        &src[x0 + r * p_len..x0 + (r + 1) * p_len],
                                        &mut next[o..o + p_len],
                                    );
                                }
                            }
                        }
                    }
                }
                prefixes *= cores.len();
                std::mem::swap(&mut input, &mut next);
            }
            for (j, row) in input.chunks_exact(width).enumerate() {
                each(c0 * slab + j, row);
            }
        }
    }

    fn at(&self, row: &[f32], u: usize) -> f32 {
        match &self.map {
            None => row[u],
            Some(m) => row[m[u] as usize],
        }
    }

    fn is_goal(&self, i: usize) -> bool {
        !self.goal.is_empty() && self.goal[i]
    }

    /// `(V, greedy action)` of core `i` from its row, as the CPU's reduction.
    fn reduce(&self, i: usize, row: &[f32]) -> (f32, u32) {
        let m = self.n_joint;
        let g = self.gamma;
        if let Some(r) = &self.rewards {
            if self.is_goal(i) {
                return (r[i], 0);
            }
            let (mut best, mut arg) = (self.at(row, 0), 0u32);
            for u in 1..m {
                let x = self.at(row, u);
                if x > best {
                    (best, arg) = (x, u as u32);
                }
            }
            return (r[i] + g * best, arg);
        }
        let (mut best, mut arg) = (0.0f32, 0u32);
        for u in 0..m {
            let r = self.reward_table[i * m + u];
            let theta = if self.is_goal(i) {
                r
            } else {
                r + g * self.at(row, u)
            };
            if u == 0 || theta > best {
                (best, arg) = (theta, u as u32);
            }
        }
        (best, arg)
    }

    fn full(&mut self, v: Buf, out: Option<Buf>, greedy: bool) {
        let mut reduced = Vec::with_capacity(self.n);
        self.expected(&self.bufs[usize::from(v.0)], |i, row| {
            reduced.push(self.reduce(i, row));
        });
        if let Some(o) = out {
            for (x, r) in self.bufs[usize::from(o.0)].iter_mut().zip(&reduced) {
                *x = r.0;
            }
        }
        if greedy {
            for (u, r) in self.policy.iter_mut().zip(&reduced) {
                *u = r.1;
            }
        }
    }
}

impl Sweeps<f32> for HostSweeps {
    type Error = SolveError;

    fn backup(&mut self, v: Buf, out: Buf) -> Result<(), SolveError> {
        self.full(v, Some(out), false);
        Ok(())
    }

    fn backup_greedy(&mut self, v: Buf, out: Buf) -> Result<(), SolveError> {
        self.full(v, Some(out), true);
        Ok(())
    }

    fn rewards(&mut self, out: Buf) -> Result<(), SolveError> {
        let r = self.rewards.as_ref().ok_or(SolveError::PolicyEvaluation)?;
        let g = self.gamma;
        for (i, x) in self.bufs[usize::from(out.0)].iter_mut().enumerate() {
            let goal = !self.goal.is_empty() && self.goal[i];
            *x = if goal { r[i] } else { r[i] + g * 0.0 };
        }
        Ok(())
    }

    fn evaluate(&mut self, v: Buf, out: Buf) -> Result<(), SolveError> {
        if !self.can_evaluate {
            return Err(SolveError::PolicyEvaluation);
        }
        let r = self.rewards.as_ref().ok_or(SolveError::PolicyEvaluation)?;
        let g = self.gamma;
        let mut values = Vec::with_capacity(self.n);
        self.expected(&self.bufs[usize::from(v.0)], |i, row| {
            values.push(r[i] + g * row[self.policy[i] as usize]);
        });
        self.bufs[usize::from(out.0)] = values;
        Ok(())
    }

    fn sweep_async(&mut self, _v: Buf) -> Result<f64, SolveError> {
        Err(SolveError::PolicyEvaluation)
    }

    fn diff_stats(&mut self, a: Buf, b: Buf, s: f32) -> Result<DiffStats, SolveError> {
        let (x, y) = (&self.bufs[usize::from(a.0)], &self.bufs[usize::from(b.0)]);
        Ok(fuzzyq_core::solver::diff_stats(x, y, s))
    }

    fn shift(&mut self, v: Buf, s: f32) -> Result<(), SolveError> {
        fuzzyq_core::solver::shift(&mut self.bufs[usize::from(v.0)], s);
        Ok(())
    }

    fn exact_delta(&mut self, a: Buf, b: Buf) -> Result<f64, SolveError> {
        let dv: Vec<f32> = self.bufs[usize::from(a.0)]
            .iter()
            .zip(&self.bufs[usize::from(b.0)])
            .map(|(&x, &y)| x - y)
            .collect();
        let mut m = 0.0f32;
        self.expected(&dv, |i, row| {
            if !self.is_goal(i) {
                for u in 0..self.n_joint {
                    let x = self.at(row, u).abs();
                    m = if m >= x { m } else { x };
                }
            }
        });
        Ok(f64::from(self.gamma * m))
    }

    fn greedy(&mut self, v: Buf) -> Result<(), SolveError> {
        self.full(v, None, true);
        Ok(())
    }

    fn load(&mut self, v: Buf, values: &[f32]) -> Result<(), SolveError> {
        fuzzyq_core::error::check_len("V", self.n, values.len())?;
        self.bufs[usize::from(v.0)].copy_from_slice(values);
        Ok(())
    }

    fn load_policy(&mut self, policy: &[u32]) -> Result<(), SolveError> {
        fuzzyq_core::error::check_len("policy", self.n, policy.len())?;
        self.policy.copy_from_slice(policy);
        Ok(())
    }

    fn values(&self, v: Buf) -> Result<Cow<'_, [f32]>, SolveError> {
        Ok(Cow::Borrowed(&self.bufs[usize::from(v.0)]))
    }

    fn policy(&self) -> Result<Cow<'_, [u32]>, SolveError> {
        Ok(Cow::Borrowed(&self.policy))
    }

    fn kernel(&self) -> Option<&'static str> {
        Some(match self.rounding {
            Rounding::Fused => "host-fused",
            Rounding::Product => "host-rounded",
        })
    }
}
