//! The floating-point scalar the kernels are written for.
//!
//! Every kernel is generic over [`Real`], implemented for `f32` and `f64` only. `f32` is what a
//! microcontroller's FPU and the fast solver want; `f64` is what parity with reference
//! implementations (which run in double precision) wants. The trait is sealed: it is a
//! switch between these two types, not an extension point.
//!
//! The few transcendental functions the kernels need come from [`libm`] so that the crate stays
//! `no_std`; this module is the one place where the math backend is chosen.

use core::fmt::{Debug, Display};
use core::iter::Sum;
use core::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

mod sealed {
    /// Seals [`Real`](super::Real) to `f32` and `f64`.
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// A floating-point scalar: `f32` or `f64`.
pub trait Real:
    sealed::Sealed
    + Copy
    + bytemuck::Pod
    + Default
    + PartialEq
    + PartialOrd
    + Debug
    + Display
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
    + Sum
{
    /// Additive identity.
    const ZERO: Self;
    /// Multiplicative identity.
    const ONE: Self;
    /// A short name of the type (`"f32"` or `"f64"`), used in file headers and messages.
    const NAME: &'static str;

    /// Converts from `f64`, rounding to nearest.
    fn from_f64(v: f64) -> Self;
    /// Converts to `f64` (exact).
    fn to_f64(self) -> f64;
    /// Whether the value is neither infinite nor NaN.
    fn is_finite(self) -> bool;
    /// Whether the value is NaN.
    #[inline]
    #[must_use]
    fn is_nan(self) -> bool {
        self.partial_cmp(&self).is_none()
    }
    /// Absolute value.
    fn abs(self) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Natural exponential.
    fn exp(self) -> Self;

    /// The larger of two values; `other` if `self` is NaN.
    #[inline]
    #[must_use]
    fn max_of(self, other: Self) -> Self {
        if self >= other { self } else { other }
    }

    /// The smaller of two values; `other` if `self` is NaN.
    #[inline]
    #[must_use]
    fn min_of(self, other: Self) -> Self {
        if self <= other { self } else { other }
    }

    /// Clamps to `[lo, hi]` (`lo <= hi` is the caller's promise).
    #[inline]
    #[must_use]
    fn clamp_to(self, lo: Self, hi: Self) -> Self {
        if self < lo {
            lo
        } else if self > hi {
            hi
        } else {
            self
        }
    }
}

impl Real for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const NAME: &'static str = "f32";

    #[inline]
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    #[inline]
    fn to_f64(self) -> f64 {
        f64::from(self)
    }
    #[inline]
    fn is_finite(self) -> bool {
        f32::is_finite(self)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabsf(self)
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrtf(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::expf(self)
    }
}

impl Real for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    const NAME: &'static str = "f64";

    #[inline]
    fn from_f64(v: f64) -> Self {
        v
    }
    #[inline]
    fn to_f64(self) -> f64 {
        self
    }
    #[inline]
    fn is_finite(self) -> bool {
        f64::is_finite(self)
    }
    #[inline]
    fn abs(self) -> Self {
        libm::fabs(self)
    }
    #[inline]
    fn sqrt(self) -> Self {
        libm::sqrt(self)
    }
    #[inline]
    fn exp(self) -> Self {
        libm::exp(self)
    }
}
