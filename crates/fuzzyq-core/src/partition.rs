//! Triangular fuzzy partitions of one state variable and their product over a state vector.
//!
//! # One variable
//! A [`Partition`] is a strictly increasing list of cores `c_0 < ... < c_{n-1}`. Membership `k`
//! is the triangle that is 1 at `c_k` and 0 at the neighbouring cores; for any value at most two
//! memberships are non-zero and they sum to 1. Values outside `[c_0, c_{n-1}]` saturate: they
//! belong to the edge core with degree 1.
//!
//! # Crisp boxes
//! A partition can also be **crisp** ([`Membership::Crisp`]): every value belongs, with degree
//! 1, to its nearest core alone. The box of core `c_k` is `[m_{k-1}, m_k)`, where `m_k` is the
//! midpoint of `c_k` and `c_{k+1}` (a value exactly on a midpoint belongs to the upper core),
//! and the edge boxes extend to infinity. The same cores then define a state aggregation (a
//! crisp grid), so the solver and the policies run unchanged on it: the clean crisp-versus-fuzzy
//! control of the paper's Table 1. Everything below holds for both kinds; a crisp state has
//! exactly one active core.
//!
//! # Product grid
//! A [`ProductPartition`] combines one partition per state variable. Its joint cores are
//! numbered in **row-major (C) order**: with per-variable core indices `(i_0, ..., i_{E-1})` the
//! flat index is `((i_0 * n_1 + i_1) * n_2 + ...) * n_{E-1} + i_{E-1}`, so the last variable
//! varies fastest. A numpy array of shape `(n_0, ..., n_{E-1})` in C order has the same layout.
//!
//! The joint membership of a core is the product of its per-variable memberships, so at most
//! `2^E` joint cores are active for any state. [`ProductPartition::active`] finds them without
//! allocating and returns an [`ActiveCores`] that visits them with a callback.
//!
//! # Why a callback and not an iterator
//! Visiting the active cores is the innermost loop of every backup and policy. A callback
//! (`for_each(|index, weight| ...)`) lets the visit run as one tight loop over a bit mask with
//! the per-variable offsets in registers, and lets the caller fuse its work (a dot product, a
//! weighted action) into it. An external iterator would have to carry the same state in a struct
//! and re-derive it on every `next`, for no gain: no caller stops early or zips two visits.

use crate::error::{CoresError, EvalError, PartitionError};
use crate::real::Real;

pub use crate::limits::MAX_DIMS;

crate::named_option! {
    /// The membership functions a [`Partition`] puts on its cores.
    #[derive(Default)]
    pub enum Membership: "membership" {
        /// Triangles: 1 at a core, 0 at its neighbours, linear between (the fuzzy partition).
        #[default]
        Triangular = "triangular" => "triangles: 1 at a core, 0 at its neighbours (fuzzy Q-iteration)",
        /// Crisp boxes: degree 1 in the nearest core, 0 elsewhere (see the [module docs](self)).
        Crisp = "crisp" => "nearest-core boxes (crisp grid Q-iteration)",
    }
}

/// A fuzzy (or crisp) partition of one state variable: a validated view of its cores.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Partition<'a, T> {
    cores: &'a [T],
    membership: Membership,
}

/// Where a value falls between the cores of a [`Partition`].
///
/// The value has membership `1 - upper_weight` in core `lower` and `upper_weight` in core
/// `lower + 1`. When the value sits exactly on a core (or saturates at an edge),
/// `upper_weight` is zero and only `lower` is active.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment<T> {
    /// Index of the lower active core.
    pub lower: usize,
    /// Membership of core `lower + 1`; zero when only `lower` is active.
    pub upper_weight: T,
}

impl<T: Real> Segment<T> {
    /// Membership of core `lower`.
    #[inline]
    #[must_use]
    pub fn lower_weight(&self) -> T {
        T::ONE - self.upper_weight
    }

    /// Whether two cores are active.
    #[inline]
    #[must_use]
    pub fn is_split(&self) -> bool {
        self.upper_weight != T::ZERO
    }
}

impl<'a, T: Real> Partition<'a, T> {
    /// Filler for unused dimensions of a [`ProductPartition`] (never validated or read).
    const EMPTY: Self = Self {
        cores: &[],
        membership: Membership::Triangular,
    };

    /// Validates `cores` (at least two, finite, strictly increasing) and wraps them.
    pub fn try_from_cores(cores: &'a [T]) -> Result<Self, CoresError> {
        if cores.len() < 2 {
            return Err(CoresError::TooFew { found: cores.len() });
        }
        for (index, &c) in cores.iter().enumerate() {
            if !c.is_finite() {
                return Err(CoresError::NotFinite { index });
            }
            if index > 0 && c <= cores[index - 1] {
                return Err(CoresError::NotIncreasing { index });
            }
        }
        Ok(Self {
            cores,
            membership: Membership::Triangular,
        })
    }

    /// The same cores with membership functions of kind `membership`.
    ///
    /// ```
    /// use fuzzyq_core::partition::{Membership, Partition};
    /// let cores = [0.0_f64, 1.0, 3.0];
    /// let crisp = Partition::try_from_cores(&cores).unwrap().with_membership(Membership::Crisp);
    /// assert_eq!(crisp.membership(1, 0.6), 1.0); // nearest core: 1.0
    /// assert_eq!(crisp.membership(1, 2.0), 0.0); // the midpoint belongs to the upper core
    /// ```
    #[must_use]
    pub fn with_membership(mut self, membership: Membership) -> Self {
        self.membership = membership;
        self
    }

    /// The kind of membership functions.
    #[inline]
    #[must_use]
    pub fn membership_kind(&self) -> Membership {
        self.membership
    }

    /// The cores, in increasing order.
    #[inline]
    #[must_use]
    pub fn cores(&self) -> &'a [T] {
        self.cores
    }

    /// Number of cores (at least 2).
    #[inline]
    #[must_use]
    pub fn n_cores(&self) -> usize {
        self.cores.len()
    }

    /// The smallest core.
    #[inline]
    #[must_use]
    pub fn first(&self) -> T {
        self.cores[0]
    }

    /// The largest core.
    #[inline]
    #[must_use]
    pub fn last(&self) -> T {
        self.cores[self.cores.len() - 1]
    }

    /// Locates a finite value between the cores (values outside saturate to the edge).
    ///
    /// The result is exact at cores: a value equal to `c_k` gives `lower = k` and weight 0.
    /// A crisp partition always gives weight 0 and `lower` = the nearest core.
    #[inline]
    #[must_use]
    pub fn locate(&self, x: T) -> Segment<T> {
        let c = self.cores;
        let n = c.len();
        if x <= c[0] {
            return Segment {
                lower: 0,
                upper_weight: T::ZERO,
            };
        }
        if x >= c[n - 1] {
            return Segment {
                lower: n - 1,
                upper_weight: T::ZERO,
            };
        }
        // c[0] < x < c[n-1]: the first core above x is at 1..n-1. (`max(1)` only matters
        // for NaN, which callers reject; it keeps the index in range regardless.)
        let above = c.partition_point(|&ck| ck <= x).max(1);
        let lower = above - 1;
        let w = (x - c[lower]) / (c[above] - c[lower]);
        if self.membership == Membership::Crisp {
            // The nearest core; the midpoint (w = 1/2) belongs to the upper one.
            let half = T::ONE / (T::ONE + T::ONE);
            return Segment {
                lower: if w < half { lower } else { above },
                upper_weight: T::ZERO,
            };
        }
        if w >= T::ONE {
            // x is within rounding of the upper core: it is that core (otherwise the lower
            // core would be "active" with membership 0).
            return Segment {
                lower: above,
                upper_weight: T::ZERO,
            };
        }
        Segment {
            lower,
            upper_weight: w,
        }
    }

    /// Membership degree of `x` in core `k` (0 for `k` out of range).
    #[must_use]
    pub fn membership(&self, k: usize, x: T) -> T {
        let s = self.locate(x);
        if k == s.lower {
            s.lower_weight()
        } else if k == s.lower + 1 {
            s.upper_weight
        } else {
            T::ZERO
        }
    }

    /// Writes the membership of `x` in every core into `out` (length [`n_cores`](Self::n_cores)).
    pub fn memberships(&self, x: T, out: &mut [T]) -> Result<(), EvalError> {
        crate::error::check_len("memberships", self.n_cores(), out.len())?;
        if !x.is_finite() {
            return Err(EvalError::NotFinite {
                what: "value",
                index: 0,
            });
        }
        out.fill(T::ZERO);
        let s = self.locate(x);
        out[s.lower] = s.lower_weight();
        if s.is_split() {
            out[s.lower + 1] = s.upper_weight;
        }
        Ok(())
    }
}

/// A product of triangular partitions: the fuzzy grid over a state vector.
///
/// Holds a view of each variable's cores (no allocation) and the row-major strides of the flat
/// core index (see the [module docs](self)).
#[derive(Clone, Copy, Debug)]
pub struct ProductPartition<'a, T> {
    dims: [Partition<'a, T>; MAX_DIMS],
    strides: [usize; MAX_DIMS],
    n_dims: usize,
    n_cores: usize,
}

impl<'a, T: Real> ProductPartition<'a, T> {
    /// Builds a grid from the cores of each state variable, validating each.
    ///
    /// ```
    /// use fuzzyq_core::ProductPartition;
    /// let pos = [-1.0_f32, 0.0, 1.0];
    /// let vel = [-2.0_f32, 2.0];
    /// let grid = ProductPartition::try_new(&[&pos[..], &vel[..]]).unwrap();
    /// assert_eq!(grid.n_cores(), 6);
    /// ```
    pub fn try_new(cores: &[&'a [T]]) -> Result<Self, PartitionError> {
        if cores.is_empty() {
            return Err(PartitionError::NoDimensions);
        }
        if cores.len() > MAX_DIMS {
            return Err(PartitionError::TooManyDimensions { found: cores.len() });
        }
        let mut dims = [Partition::EMPTY; MAX_DIMS];
        for (dim, c) in cores.iter().enumerate() {
            dims[dim] = Partition::try_from_cores(c)
                .map_err(|error| PartitionError::Cores { dim, error })?;
        }
        Self::from_partitions(&dims[..cores.len()])
    }

    /// Builds a grid from already validated partitions.
    pub fn from_partitions(parts: &[Partition<'a, T>]) -> Result<Self, PartitionError> {
        if parts.is_empty() {
            return Err(PartitionError::NoDimensions);
        }
        if parts.len() > MAX_DIMS {
            return Err(PartitionError::TooManyDimensions { found: parts.len() });
        }
        let mut dims = [Partition::EMPTY; MAX_DIMS];
        dims[..parts.len()].copy_from_slice(parts);
        let mut strides = [0usize; MAX_DIMS];
        let mut n: usize = 1;
        for e in (0..parts.len()).rev() {
            strides[e] = n;
            n = n
                .checked_mul(parts[e].n_cores())
                .ok_or(PartitionError::TooManyCores)?;
        }
        Ok(Self {
            dims,
            strides,
            n_dims: parts.len(),
            n_cores: n,
        })
    }

    /// The same grid with membership functions of kind `membership` on every variable.
    #[must_use]
    pub fn with_membership(mut self, membership: Membership) -> Self {
        for d in &mut self.dims[..self.n_dims] {
            *d = d.with_membership(membership);
        }
        self
    }

    /// The kind of membership functions (that of the first variable; [`with_membership`]
    /// sets all alike).
    ///
    /// [`with_membership`]: Self::with_membership
    #[must_use]
    pub fn membership_kind(&self) -> Membership {
        self.dims[0].membership
    }

    /// Number of state variables `E`.
    #[inline]
    #[must_use]
    pub fn n_dims(&self) -> usize {
        self.n_dims
    }

    /// Number of joint cores `N` (the product of the per-variable core counts).
    #[inline]
    #[must_use]
    pub fn n_cores(&self) -> usize {
        self.n_cores
    }

    /// The partition of state variable `dim`.
    ///
    /// # Panics
    /// If `dim >= n_dims()`.
    #[inline]
    #[must_use]
    pub fn dim(&self, dim: usize) -> Partition<'a, T> {
        assert!(dim < self.n_dims, "dimension {dim} out of range");
        self.dims[dim]
    }

    /// The partitions of all state variables.
    #[inline]
    #[must_use]
    pub fn dims(&self) -> &[Partition<'a, T>] {
        &self.dims[..self.n_dims]
    }

    /// Row-major strides of the flat core index, one per state variable.
    #[inline]
    #[must_use]
    pub fn strides(&self) -> &[usize] {
        &self.strides[..self.n_dims]
    }

    /// Per-variable core indices of flat core `index` (row-major), written into `out`.
    pub fn unravel(&self, index: usize, out: &mut [usize]) -> Result<(), EvalError> {
        crate::error::check_len("core indices", self.n_dims, out.len())?;
        if index >= self.n_cores {
            return Err(EvalError::OutOfRange {
                what: "core",
                index,
                len: self.n_cores,
            });
        }
        let mut rest = index;
        for e in 0..self.n_dims {
            out[e] = rest / self.strides[e];
            rest %= self.strides[e];
        }
        Ok(())
    }

    /// Coordinates of flat core `index`: the state at which its membership is 1.
    pub fn core_state(&self, index: usize, out: &mut [T]) -> Result<(), EvalError> {
        crate::error::check_len("state", self.n_dims, out.len())?;
        let mut idx = [0usize; MAX_DIMS];
        self.unravel(index, &mut idx[..self.n_dims])?;
        for e in 0..self.n_dims {
            out[e] = self.dims[e].cores[idx[e]];
        }
        Ok(())
    }

    /// Finds the active cores of state `x` (length `E`, finite).
    pub fn active(&self, x: &[T]) -> Result<ActiveCores<T>, EvalError> {
        crate::error::check_len("state", self.n_dims, x.len())?;
        if let Some(index) = x.iter().position(|v| !v.is_finite()) {
            return Err(EvalError::NotFinite {
                what: "state",
                index,
            });
        }
        Ok(self.active_unchecked(x))
    }

    /// [`active`](Self::active) with the cores numbered by `strides` (a per-core table in
    /// another layout than row-major: core `(i_0, ..)` at `sum_d i_d strides[d]`). The cores
    /// come in the same order with the same weights, so interpolating a table gives the bits
    /// of the row-major table's interpolation.
    pub fn active_with_strides(
        &self,
        x: &[T],
        strides: &[usize],
    ) -> Result<ActiveCores<T>, EvalError> {
        crate::error::check_len("strides", self.n_dims, strides.len())?;
        self.active(x)?;
        Ok(self.active_at(x, strides))
    }

    /// [`active`](Self::active) for a state the caller knows has length `E` and finite values.
    ///
    /// A wrong length or a NaN gives a meaningless (but memory-safe) result; the solver uses
    /// this on states that its model produced and it already checked.
    #[inline]
    #[must_use]
    pub fn active_unchecked(&self, x: &[T]) -> ActiveCores<T> {
        self.active_at(x, &self.strides[..self.n_dims])
    }

    /// [`Self::active_unchecked`] with the cores numbered by `strides` (`E` of them).
    #[inline]
    fn active_at(&self, x: &[T], strides: &[usize]) -> ActiveCores<T> {
        let mut a = ActiveCores {
            base: 0,
            base_weight: T::ONE,
            split_stride: [0; MAX_DIMS],
            split_lower: [T::ZERO; MAX_DIMS],
            split_upper: [T::ZERO; MAX_DIMS],
            n_split: 0,
        };
        for e in 0..self.n_dims {
            let s = self.dims[e].locate(x[e]);
            a.base += s.lower * strides[e];
            if s.is_split() {
                a.split_stride[a.n_split] = strides[e];
                a.split_lower[a.n_split] = s.lower_weight();
                a.split_upper[a.n_split] = s.upper_weight;
                a.n_split += 1;
            }
        }
        a
    }

    /// Membership of state `x` in flat core `index` (the product of per-variable memberships).
    pub fn membership(&self, index: usize, x: &[T]) -> Result<T, EvalError> {
        let mut idx = [0usize; MAX_DIMS];
        self.unravel(index, &mut idx[..self.n_dims])?;
        crate::error::check_len("state", self.n_dims, x.len())?;
        let mut mu = T::ONE;
        for e in 0..self.n_dims {
            mu *= self.dims[e].membership(idx[e], x[e]);
        }
        Ok(mu)
    }
}

/// The active cores of one state: at most `2^E` flat indices with weights summing to 1.
///
/// Produced by [`ProductPartition::active`]; visit them with [`for_each`](Self::for_each).
#[derive(Clone, Copy, Debug)]
pub struct ActiveCores<T> {
    base: usize,
    base_weight: T,
    split_stride: [usize; MAX_DIMS],
    split_lower: [T; MAX_DIMS],
    split_upper: [T; MAX_DIMS],
    n_split: usize,
}

impl<T: Real> ActiveCores<T> {
    /// One active core with membership 1: the crisp cell `index` of a partition that is not a
    /// product of triangles (for example a vector quantiser's codebook).
    #[inline]
    #[must_use]
    pub fn single(index: usize) -> Self {
        Self {
            base: index,
            base_weight: T::ONE,
            split_stride: [0; MAX_DIMS],
            split_lower: [T::ZERO; MAX_DIMS],
            split_upper: [T::ZERO; MAX_DIMS],
            n_split: 0,
        }
    }

    /// Number of active cores: `2^s` where `s` is the number of variables that fall strictly
    /// between two cores.
    #[inline]
    #[must_use]
    pub fn len(&self) -> usize {
        1 << self.n_split
    }

    /// Always false: every state has at least one active core.
    #[inline]
    #[must_use]
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Calls `f(flat_index, weight)` for every active core, in increasing flat index.
    ///
    /// The weight of a core is the product of its per-variable memberships, multiplied in
    /// variable order, so the same state always gives bit-identical weights. Each
    /// per-variable membership is positive; their product can underflow to 0 when several are
    /// tiny (below about `1e-154` in `f64`).
    #[inline]
    pub fn for_each(&self, mut f: impl FnMut(usize, T)) {
        let s = self.n_split;
        for mask in 0..(1usize << s) {
            let mut index = self.base;
            let mut w = self.base_weight;
            // Bit (s-1-j) of the mask selects the upper core of split variable j, so the
            // variable with the largest stride is the most significant bit and the visit runs
            // in increasing flat index.
            for j in 0..s {
                if (mask >> (s - 1 - j)) & 1 == 1 {
                    index += self.split_stride[j];
                    w *= self.split_upper[j];
                } else {
                    w *= self.split_lower[j];
                }
            }
            f(index, w);
        }
    }

    /// Writes the active cores' flat indices and memberships into `index` and `weight`, in the
    /// order and with the products of [`Self::for_each`] (bit-identical weights), and returns
    /// how many there are; `None` (nothing written) if the buffers hold fewer than `2^s`.
    ///
    /// Filled a split variable at a time, so each core costs one multiply and one add: the
    /// fast path for code that visits the cores more than once or gathers their table values
    /// together.
    #[inline]
    pub fn write_to(&self, index: &mut [usize], weight: &mut [T]) -> Option<usize> {
        let n = 1usize.checked_shl(self.n_split as u32)?;
        if index.len() < n || weight.len() < n {
            return None;
        }
        index[0] = self.base;
        weight[0] = self.base_weight;
        for j in 0..self.n_split {
            let (stride, lo, hi) = (
                self.split_stride[j],
                self.split_lower[j],
                self.split_upper[j],
            );
            // Core `i` of the first `2^j` becomes cores `2i` (lower) and `2i + 1` (upper):
            // split variable 0 ends up the most significant bit, as in `for_each`. (Sliced to
            // `2^(j+1)` first, so that the indexing below needs no bounds checks.)
            let m = 1usize << j;
            let (index, weight) = (&mut index[..2 * m], &mut weight[..2 * m]);
            for i in (0..m).rev() {
                let (d, w) = (index[i], weight[i]);
                index[2 * i + 1] = d + stride;
                weight[2 * i + 1] = w * hi;
                index[2 * i] = d;
                weight[2 * i] = w * lo;
            }
        }
        Some(n)
    }

    /// Sum of `weight * values[index]` over the active cores: the fuzzy interpolation of a
    /// per-core table (for example a value function `V`) at the state.
    ///
    /// `values` must cover every active index (`values.len() >= n_cores` of the grid).
    #[inline]
    #[must_use]
    pub fn interpolate(&self, values: &[T]) -> T {
        let mut acc = T::ZERO;
        self.for_each(|d, w| acc += w * values[d]);
        acc
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn write_to_lists_for_each_bit_for_bit() {
        let c = [0.0f64, 0.3, 1.0, 2.5];
        for dims in [1usize, 3, 6] {
            let parts = std::vec![&c[..]; dims];
            let g = ProductPartition::try_new(&parts).unwrap();
            for x in [0.1, 0.3, 1.7, 2.5, 2.2] {
                let xs = std::vec![x; dims];
                let active = g.active(&xs).unwrap();
                let mut want = std::vec::Vec::new();
                active.for_each(|d, w| want.push((d, w.to_bits())));
                let (mut idx, mut w) = ([0usize; 64], [0.0f64; 64]);
                let n = active.write_to(&mut idx, &mut w).unwrap();
                let got: std::vec::Vec<_> = idx[..n]
                    .iter()
                    .zip(&w[..n])
                    .map(|(&d, w)| (d, w.to_bits()))
                    .collect();
                assert_eq!(got, want, "{dims} dims at {x}");
                if n > 1 {
                    assert!(active.write_to(&mut idx[..n - 1], &mut w).is_none());
                }
            }
        }
    }

    #[test]
    fn rejects_bad_cores() {
        assert_eq!(
            Partition::try_from_cores(&[1.0f32]),
            Err(CoresError::TooFew { found: 1 })
        );
        assert_eq!(
            Partition::try_from_cores(&[0.0f64, f64::NAN]),
            Err(CoresError::NotFinite { index: 1 })
        );
        assert_eq!(
            Partition::try_from_cores(&[0.0f64, 1.0, 1.0]),
            Err(CoresError::NotIncreasing { index: 2 })
        );
        assert!(matches!(
            ProductPartition::<f32>::try_new(&[]),
            Err(PartitionError::NoDimensions)
        ));
    }

    #[test]
    fn locate_is_exact_at_cores_and_saturates() {
        let c = [-6.0f32, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0];
        let p = Partition::try_from_cores(&c).unwrap();
        for (k, &ck) in c.iter().enumerate() {
            let s = p.locate(ck);
            assert_eq!(s.lower, k);
            assert_eq!(s.upper_weight, 0.0);
        }
        assert_eq!(p.locate(-100.0).lower, 0);
        assert_eq!(p.locate(100.0).lower, 8);
        let s = p.locate(1.5);
        assert_eq!(s.lower, 6);
        assert!((s.upper_weight - (1.2 / 2.7)).abs() < 1e-6);
    }

    #[test]
    fn values_within_rounding_of_a_core_are_that_core() {
        // Regression: (x - c_i) / (c_{i+1} - c_i) rounds to 1 for x just below c_{i+1}, which
        // left core i active with membership 0.
        let c = [-3.0f64, 0.0, 3.0];
        let p = Partition::try_from_cores(&c).unwrap();
        let s = p.locate(-7.7e-203);
        assert_eq!((s.lower, s.upper_weight), (1, 0.0));
        let mut mu = [0.0; 3];
        p.memberships(-7.7e-203, &mut mu).unwrap();
        assert_eq!(mu, [0.0, 1.0, 0.0]);
    }

    #[test]
    fn flat_order_is_row_major() {
        let a = [0.0f64, 1.0, 2.0];
        let b = [0.0f64, 1.0];
        let g = ProductPartition::try_new(&[&a[..], &b[..]]).unwrap();
        assert_eq!(g.strides(), &[2, 1]);
        let mut x = [0.0; 2];
        g.core_state(3, &mut x).unwrap();
        assert_eq!(x, [1.0, 1.0]);
        let act = g.active(&[1.5, 0.25]).unwrap();
        let mut seen = [(0usize, 0.0f64); 4];
        let mut n = 0;
        act.for_each(|d, w| {
            seen[n] = (d, w);
            n += 1;
        });
        assert_eq!(n, 4);
        assert_eq!(
            seen.map(|s| s.0),
            [2, 3, 4, 5],
            "active cores in increasing flat order"
        );
        assert!((seen[0].1 - 0.5 * 0.75).abs() < 1e-12);
        assert!((seen[3].1 - 0.5 * 0.25).abs() < 1e-12);
    }
}
