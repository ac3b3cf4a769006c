//! Where the passes over `V` run. The iteration drivers ([`solve_on`](super::solve_on),
//! [`solve_from`](super::solve_from)) keep a run's scalar state (sweep records, stopping rule,
//! extrapolation shifts, evaluation budget) and ask a [`Sweeps`] backend for every pass over
//! the values: [`Local`] holds `V` in this process, and a backend that holds it in shards
//! elsewhere (`fuzzyq.distributed` on Ray) computes each pass from the slab entry points
//! ([`Operator::apply_slabs`] and its siblings). Every reduction a driver asks for is a maximum
//! or a minimum, so any backend that computes each core's value as the local one does returns
//! the same run bit for bit.

use std::borrow::Cow;
use std::vec::Vec;

use super::{Operator, Reduce, SolveError, par};
use crate::model::Model;
use crate::real::Real;

/// Elements per task of the passes over `V` between sweeps.
pub(super) const PASS_CHUNK: usize = 1 << 16;

/// One of the three value buffers of a [`Sweeps`] backend: `Buf(0)`, `Buf(1)` or `Buf(2)`.
/// Each holds one value per core in the operator's internal order, and starts at 0.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Buf(pub u8);

/// The change between two value buffers `a` and `b` after a shift `s` of `a`'s input:
/// `max |a - b + s|` and the range of `a - b`, in `f64` ([`diff_stats`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DiffStats {
    /// `max_i |(a_i - b_i) + s|`.
    pub change: f64,
    /// `min_i (a_i - b_i)`.
    pub lo: f64,
    /// `max_i (a_i - b_i)`.
    pub hi: f64,
}

impl DiffStats {
    /// The statistics of no cores (the identity of [`Self::merge`]).
    pub const EMPTY: Self = Self {
        change: 0.0,
        lo: f64::INFINITY,
        hi: f64::NEG_INFINITY,
    };

    /// The statistics of two disjoint sets of cores together: exact in any grouping.
    #[must_use]
    pub fn merge(self, other: Self) -> Self {
        Self {
            change: self.change.max(other.change),
            lo: self.lo.min(other.lo),
            hi: self.hi.max(other.hi),
        }
    }
}

/// [`DiffStats`] of `a` against `b` (equal lengths; extra values of either are ignored) with
/// shift `s`: maxima and minima in `f64`, the same bits for any split of the cores. (NaN
/// differences are skipped.)
pub fn diff_stats<T: Real>(a: &[T], b: &[T], s: T) -> DiffStats {
    let s = s.to_f64();
    par::map_reduce(
        a.len().min(b.len()),
        PASS_CHUNK,
        DiffStats::EMPTY,
        |r| {
            let (lo, hi) = diff_range(&a[r.clone()], &b[r]);
            DiffStats::of_range(lo, hi, s)
        },
        DiffStats::merge,
    )
}

impl DiffStats {
    /// The statistics of differences whose range is `[lo, hi]` (`lo > hi`: none) after a
    /// shift `s`. Rounding `d + s` is monotone in `d`, so `max |d + s|` is taken at an end of
    /// the range: the same bits as the maximum over every difference.
    #[must_use]
    pub fn of_range(lo: f64, hi: f64, s: f64) -> Self {
        if lo > hi {
            return Self::EMPTY;
        }
        // A zero bound's sign depends on which lane met which zero first: `+ 0.0` makes every
        // zero `+0`, so the bits do not depend on the split either.
        let (lo, hi) = (lo + 0.0, hi + 0.0);
        Self {
            change: (lo + s).abs().max((hi + s).abs()),
            lo,
            hi,
        }
    }
}

/// `(min, max)` of `a[i] - b[i]` in `f64` (`(inf, -inf)` for none; NaN differences skipped).
fn diff_range<T: Real>(a: &[T], b: &[T]) -> (f64, f64) {
    diff_range_by(a, b, &|&x: &T| x)
}

pub(super) use super::simd::diff_range_by;

/// Adds `s` to every value of `v` (in `T`: the extrapolation's shift).
pub fn shift<T: Real>(v: &mut [T], s: T) {
    if s == T::ZERO {
        return;
    }
    par::for_each_chunk_mut(
        v,
        PASS_CHUNK,
        || (),
        |_, _, c| {
            for x in c {
                *x += s;
            }
        },
    );
}

/// The passes over `V` an iteration driver runs, on three value buffers ([`Buf`]) and one
/// policy buffer (a joint action per core), all in the operator's internal order and all
/// starting at 0. A backend computes each pass as [`Local`] does, bit for bit; where it holds
/// the buffers (memory, shards on other machines) is its business.
pub trait Sweeps<T: Real> {
    /// What a pass can fail with besides the solver's own errors (a lost cluster, say).
    type Error: From<SolveError>;

    /// `out = max_u (rho + gamma P v)`: one synchronous backup.
    fn backup(&mut self, v: Buf, out: Buf) -> Result<(), Self::Error>;
    /// [`Self::backup`], and the policy buffer set to each core's greedy joint action (the
    /// lowest-index maximiser).
    fn backup_greedy(&mut self, v: Buf, out: Buf) -> Result<(), Self::Error>;
    /// `out = max_u (rho + gamma P 0)`, the backup of `V = 0`, without a pass over `P`
    /// (state-only rewards: every action ties).
    fn rewards(&mut self, out: Buf) -> Result<(), Self::Error>;
    /// `out = rho + gamma P_policy v` under the policy buffer: one evaluation sweep.
    fn evaluate(&mut self, v: Buf, out: Buf) -> Result<(), Self::Error>;
    /// One asynchronous sweep of `v` in place; returns `||V_new - V_old||_inf`.
    fn sweep_async(&mut self, v: Buf) -> Result<f64, Self::Error>;
    /// [`diff_stats`] of `a` against `b` with shift `s`.
    fn diff_stats(&mut self, a: Buf, b: Buf, s: T) -> Result<DiffStats, Self::Error>;
    /// Adds `s` to every value of `v` ([`shift`]).
    fn shift(&mut self, v: Buf, s: T) -> Result<(), Self::Error>;
    /// `gamma max_{d non-goal, u} |(P (a - b))[d, u]|`, the exact change of theta between the
    /// sweeps whose inputs were `b` and `a`.
    fn exact_delta(&mut self, a: Buf, b: Buf) -> Result<f64, Self::Error>;
    /// Sets the policy buffer to the greedy joint actions of `v`.
    fn greedy(&mut self, v: Buf) -> Result<(), Self::Error>;
    /// Sets `v` to `values` (one per core): a resumed run's state.
    fn load(&mut self, v: Buf, values: &[T]) -> Result<(), Self::Error>;
    /// Sets the policy buffer to `policy` (one joint action per core).
    fn load_policy(&mut self, policy: &[u32]) -> Result<(), Self::Error>;
    /// Every value of `v`.
    fn values(&self, v: Buf) -> Result<Cow<'_, [T]>, Self::Error>;
    /// The policy buffer.
    fn policy(&self) -> Result<Cow<'_, [u32]>, Self::Error>;
    /// Every value of `v` handed to `each` a piece at a time, as `each(first, values)` with
    /// `first` the index of `values[0]`: consecutive pieces covering every core once, in
    /// order, each of whole slabs on the block path
    /// ([`SlabLayout::slab_len`](super::SlabLayout::slab_len)). The result's `V` is put in
    /// grid order piece by piece, so a backend that holds `V` elsewhere (a GPU) need never
    /// have all of it on the host twice; the default hands over [`Self::values`] whole.
    fn values_by_piece(
        &self,
        v: Buf,
        each: &mut dyn FnMut(usize, &[T]),
    ) -> Result<(), Self::Error> {
        each(0, &self.values(v)?);
        Ok(())
    }
    /// The policy buffer a piece at a time ([`Self::values_by_piece`]).
    fn policy_by_piece(&self, each: &mut dyn FnMut(usize, &[u32])) -> Result<(), Self::Error> {
        each(0, &self.policy()?);
        Ok(())
    }
    /// What computes the passes, for [`Solution::kernel`](super::Solution::kernel) (`None`:
    /// the operator's CPU kernel instance).
    fn kernel(&self) -> Option<&'static str> {
        None
    }
}

/// One value per core of `op` in grid order, from `fill`, which hands over the values in
/// internal order a piece at a time ([`Sweeps::values_by_piece`]).
///
/// # Panics
/// If the pieces are not of whole slabs on the block path, or overrun the cores.
pub(super) fn grid_order<T, M, U, E>(
    op: &Operator<'_, T, M>,
    fill: impl FnOnce(&mut dyn FnMut(usize, &[U])) -> Result<(), E>,
) -> Result<Vec<U>, E>
where
    T: Real,
    M: Model<T> + Sync + ?Sized,
    U: bytemuck::Pod + Default + Send + Sync,
{
    let mut out = vec![U::default(); op.n_cores()];
    let placer = match &op.path {
        super::Path::Block(b) => Some((b.slab_placer(), b.slab_len())),
        super::Path::Generic(_) => None,
    };
    fill(&mut |first, piece| match &placer {
        None => out[first..first + piece.len()].copy_from_slice(piece),
        Some((placer, slab_len)) => {
            assert!(first.is_multiple_of(*slab_len), "pieces of whole slabs");
            placer.place(first / slab_len, piece, &mut out);
        }
    })?;
    Ok(out)
}

/// The in-process backend: the buffers in memory, each pass on the operator's threads.
/// Buffers are allocated on first use, so a run holds only the ones its scheme needs.
pub struct Local<'o, 'a, T: Real, M: ?Sized> {
    op: &'o Operator<'a, T, M>,
    bufs: [Vec<T>; 3],
    policy: Vec<u32>,
    /// The generic path's (value, action) pairs of a greedy backup, kept between sweeps.
    pairs: Vec<(T, u32)>,
    /// `(out, v, range of out - v)` of the last sweep, taken while it ran, for as long as
    /// neither buffer has changed since: [`Sweeps::diff_stats`] of that pair needs no pass.
    range: Option<(Buf, Buf, (f64, f64))>,
}

impl<'o, 'a, T: Real, M: Model<T> + Sync + ?Sized> Local<'o, 'a, T, M> {
    /// A backend over `op` with every buffer at 0.
    #[must_use]
    pub fn new(op: &'o Operator<'a, T, M>) -> Self {
        Self {
            op,
            bufs: [Vec::new(), Vec::new(), Vec::new()],
            policy: Vec::new(),
            pairs: Vec::new(),
            range: None,
        }
    }

    fn buf(&mut self, b: Buf) -> &mut Vec<T> {
        let n = self.op.n_cores();
        let v = &mut self.bufs[usize::from(b.0)];
        if v.len() != n {
            v.resize(n, T::ZERO);
        }
        v
    }

    fn policy_buf(&mut self) -> &mut Vec<u32> {
        let n = self.op.n_cores();
        if self.policy.len() != n {
            self.policy.resize(n, 0);
        }
        &mut self.policy
    }

    /// Buffers `a` (read) and `b` (written), distinct.
    fn pair(&mut self, a: Buf, b: Buf) -> (&[T], &mut [T]) {
        assert_ne!(a, b, "a pass reads and writes distinct buffers");
        self.buf(a);
        self.buf(b);
        let [x, y, z] = &mut self.bufs;
        match (a.0, b.0) {
            (0, 1) => (x, y),
            (0, 2) => (x, z),
            (1, 0) => (y, x),
            (1, 2) => (y, z),
            (2, 0) => (z, x),
            (2, 1) => (z, y),
            _ => unreachable!("buffers are 0, 1 and 2"),
        }
    }
}

impl<T: Real, M: Model<T> + Sync + ?Sized> Sweeps<T> for Local<'_, '_, T, M> {
    type Error = SolveError;

    fn backup(&mut self, v_buf: Buf, out_buf: Buf) -> Result<(), SolveError> {
        let op = self.op;
        self.range = None;
        let (v, out) = self.pair(v_buf, out_buf);
        let range = op.each_core_range(v, None, out, Reduce::Max, |r| r.0, |&x| x)?;
        self.range = range.map(|r| (out_buf, v_buf, r));
        Ok(())
    }

    fn backup_greedy(&mut self, v_buf: Buf, out_buf: Buf) -> Result<(), SolveError> {
        let op = self.op;
        self.range = None;
        self.policy_buf();
        let (mut policy, mut pairs) = (
            core::mem::take(&mut self.policy),
            core::mem::take(&mut self.pairs),
        );
        let (v, out) = self.pair(v_buf, out_buf);
        let range = op.each_core_greedy(v, (out, &mut policy), &mut pairs);
        (self.policy, self.pairs) = (policy, pairs);
        self.range = range?.map(|r| (out_buf, v_buf, r));
        Ok(())
    }

    fn rewards(&mut self, out: Buf) -> Result<(), SolveError> {
        let op = self.op;
        self.range = None;
        par::for_each_chunk_mut(
            self.buf(out),
            PASS_CHUNK,
            || (),
            |_, i, c| {
                for (k, o) in c.iter_mut().enumerate() {
                    *o = op.finish_max(i * PASS_CHUNK + k, T::ZERO);
                }
            },
        );
        Ok(())
    }

    fn evaluate(&mut self, v_buf: Buf, out_buf: Buf) -> Result<(), SolveError> {
        let op = self.op;
        self.range = None;
        self.policy_buf();
        let policy = core::mem::take(&mut self.policy);
        let (v, out) = self.pair(v_buf, out_buf);
        let range = op.each_core_range(v, Some(&policy), out, Reduce::Max, |r| r.0, |&x| x);
        self.policy = policy;
        self.range = range?.map(|r| (out_buf, v_buf, r));
        Ok(())
    }

    fn sweep_async(&mut self, v: Buf) -> Result<f64, SolveError> {
        let op = self.op;
        self.range = None;
        op.sweep_async(self.buf(v))
    }

    fn diff_stats(&mut self, a: Buf, b: Buf, s: T) -> Result<DiffStats, SolveError> {
        if let Some((x, y, (lo, hi))) = self.range
            && (x, y) == (a, b)
        {
            return Ok(DiffStats::of_range(lo, hi, s.to_f64()));
        }
        let (a, b) = self.pair(a, b);
        Ok(diff_stats(a, b, s))
    }

    fn shift(&mut self, v: Buf, s: T) -> Result<(), SolveError> {
        if s != T::ZERO {
            self.range = None;
        }
        shift(self.buf(v), s);
        Ok(())
    }

    fn exact_delta(&mut self, a: Buf, b: Buf) -> Result<f64, SolveError> {
        let op = self.op;
        let (a, b) = self.pair(a, b);
        let dv: Vec<T> = a.iter().zip(b.iter()).map(|(&x, &y)| x - y).collect();
        Ok(op.abs_max(&dv)?.to_f64())
    }

    fn greedy(&mut self, v: Buf) -> Result<(), SolveError> {
        let op = self.op;
        let mut policy = core::mem::take(&mut self.policy);
        policy.resize(op.n_cores(), 0);
        let r = op.greedy_internal(self.buf(v), &mut policy);
        self.policy = policy;
        r
    }

    fn load(&mut self, v: Buf, values: &[T]) -> Result<(), SolveError> {
        crate::error::check_len("V", self.op.n_cores(), values.len())?;
        self.range = None;
        self.buf(v).copy_from_slice(values);
        Ok(())
    }

    fn load_policy(&mut self, policy: &[u32]) -> Result<(), SolveError> {
        crate::error::check_len("policy", self.op.n_cores(), policy.len())?;
        self.policy_buf().copy_from_slice(policy);
        Ok(())
    }

    fn values(&self, v: Buf) -> Result<Cow<'_, [T]>, SolveError> {
        let b = &self.bufs[usize::from(v.0)];
        Ok(if b.is_empty() {
            Cow::Owned(self.op.zeros())
        } else {
            Cow::Borrowed(&b[..])
        })
    }

    fn policy(&self) -> Result<Cow<'_, [u32]>, SolveError> {
        Ok(if self.policy.is_empty() {
            Cow::Owned(std::vec![0; self.op.n_cores()])
        } else {
            Cow::Borrowed(&self.policy[..])
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::vec::Vec;

    /// The definition: every difference in turn.
    fn naive<T: Real>(a: &[T], b: &[T], s: T) -> DiffStats {
        let s = s.to_f64();
        a.iter().zip(b).fold(DiffStats::EMPTY, |m, (&x, &y)| {
            let d = x.to_f64() - y.to_f64();
            DiffStats {
                change: m.change.max((d + s).abs()),
                lo: m.lo.min(d) + 0.0,
                hi: m.hi.max(d) + 0.0,
            }
        })
    }

    fn bits(d: DiffStats) -> [u64; 3] {
        [d.change.to_bits(), d.lo.to_bits(), d.hi.to_bits()]
    }

    /// The lane-wise range and the change taken at its ends give the definition's bits, for
    /// lengths around the lane count and the pass chunk, shifts of either sign, ties, zeros
    /// of both signs and NaN differences.
    #[test]
    fn diff_stats_match_the_definition_bit_for_bit() {
        let mut r: u64 = 0x2545_F491_4F6C_DD1D;
        let mut next = move || {
            r ^= r << 13;
            r ^= r >> 7;
            r ^= r << 17;
            r
        };
        for n in [0usize, 1, 7, 8, 9, 31, PASS_CHUNK + 5] {
            for case in 0..4 {
                let mut a: Vec<f32> = (0..n)
                    .map(|_| (next() % 2001) as f32 / 100.0 - 10.0)
                    .collect();
                let mut b: Vec<f32> = (0..n)
                    .map(|_| (next() % 2001) as f32 / 100.0 - 10.0)
                    .collect();
                match case {
                    1 => b.clone_from(&a),
                    2 => {
                        for (i, (x, y)) in a.iter_mut().zip(&mut b).enumerate() {
                            (*x, *y) = if i % 2 == 0 { (-0.0, 0.0) } else { (0.0, -0.0) };
                        }
                    }
                    3 if n > 2 => {
                        a[n / 2] = f32::NAN;
                        b[1] = f32::NAN;
                    }
                    _ => {}
                }
                for s in [0.0f32, 0.37, -1.25, -12.5] {
                    let want = naive(&a, &b, s);
                    assert_eq!(
                        bits(diff_stats(&a, &b, s)),
                        bits(want),
                        "n {n}, case {case}, s {s}"
                    );
                    let (a64, b64): (Vec<f64>, Vec<f64>) = a
                        .iter()
                        .zip(&b)
                        .map(|(&x, &y)| (f64::from(x) * 1.1, f64::from(y) * 0.9))
                        .unzip();
                    let s64 = f64::from(s);
                    assert_eq!(
                        bits(diff_stats(&a64, &b64, s64)),
                        bits(naive(&a64, &b64, s64))
                    );
                }
            }
        }
        assert_eq!(
            bits(diff_stats::<f32>(&[], &[], 1.0)),
            bits(DiffStats::EMPTY)
        );
    }
}
