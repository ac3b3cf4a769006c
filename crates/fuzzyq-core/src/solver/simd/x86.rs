//! The x86-64 instances of [`Isa`]: AVX-512F (with VL, for the narrow rows it runs in AVX2) and
//! AVX2 + FMA, in `f32` and `f64`.
#![allow(unsafe_code)] // SIMD intrinsics: unaligned loads and stores through raw pointers.

use core::arch::x86_64::*;

use super::Isa;

/// AVX-512F instance (compiled with AVX-512VL too); not in a development build on a CPU
/// without AVX-512 (build.rs).
#[cfg(fuzzyq_avx512)]
pub(super) struct Avx512;
/// AVX2 + FMA instance.
pub(super) struct Avx2;

#[cfg(fuzzyq_avx512)]
impl Isa<f32> for Avx512 {
    type V = __m512;
    type M = __mmask16;
    const LANES: usize = 16;
    const BLOCK: usize = 8;
    const MERGED: usize = 4;
    const MASK_COMPARES: bool = true;
    const OVERREAD: usize = 0;
    type Exact = Self;
    type Narrow = Avx2;
    #[inline(always)]
    unsafe fn zero() -> __m512 {
        unsafe { _mm512_setzero_ps() }
    }
    #[inline(always)]
    unsafe fn neg_inf() -> __m512 {
        unsafe { _mm512_set1_ps(f32::NEG_INFINITY) }
    }
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m512 {
        unsafe { _mm512_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn mask(n: usize) -> __mmask16 {
        ((1u32 << n) - 1) as __mmask16
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> __m512 {
        unsafe { _mm512_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn load_part(p: *const f32, m: __mmask16) -> __m512 {
        unsafe { _mm512_maskz_loadu_ps(m, p) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: __m512) {
        unsafe { _mm512_storeu_ps(p, v) }
    }
    #[inline(always)]
    unsafe fn store_part(p: *mut f32, v: __m512, m: __mmask16, _n: usize) {
        unsafe { _mm512_mask_storeu_ps(p, m, v) }
    }
    const RANGE_STORES: bool = true;
    #[inline(always)]
    unsafe fn store_range(p: *mut f32, v: __m512, lo: usize, hi: usize) {
        let m = (((1u32 << hi) - 1) & !((1u32 << lo) - 1)) as __mmask16;
        unsafe { _mm512_mask_storeu_ps(p, m, v) }
    }
    #[inline(always)]
    unsafe fn equal_bits(v: __m512, t: f32, m: __mmask16) -> u64 {
        (unsafe { _mm512_mask_cmpeq_ps_mask(m, v, _mm512_set1_ps(t)) }) as u64
    }
    #[inline(always)]
    unsafe fn fma(a: __m512, b: __m512, c: __m512) -> __m512 {
        unsafe { _mm512_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    unsafe fn max(a: __m512, b: __m512) -> __m512 {
        unsafe { _mm512_max_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn abs(a: __m512) -> __m512 {
        unsafe { _mm512_abs_ps(a) }
    }
    #[inline(always)]
    unsafe fn reduce_max(v: __m512, m: __mmask16) -> f32 {
        // Not `_mm512_mask_reduce_max_ps`: it fills the masked-off lanes with the lowest
        // finite value, not minus infinity, so lanes all minus infinity reduced to it.
        unsafe { _mm512_reduce_max_ps(<Self as Isa<f32>>::load_part_from(v, m)) }
    }
    #[inline(always)]
    unsafe fn load_part_from(v: __m512, m: __mmask16) -> __m512 {
        unsafe { _mm512_mask_mov_ps(_mm512_set1_ps(f32::NEG_INFINITY), m, v) }
    }
    #[inline(always)]
    unsafe fn fma1(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }
    #[inline(always)]
    unsafe fn max1(a: f32, b: f32) -> f32 {
        if a >= b { a } else { b }
    }
}

#[cfg(fuzzyq_avx512)]
impl Isa<f64> for Avx512 {
    type V = __m512d;
    type M = __mmask8;
    const LANES: usize = 8;
    const BLOCK: usize = 8;
    const MERGED: usize = 4;
    const MASK_COMPARES: bool = true;
    const OVERREAD: usize = 0;
    type Exact = Self;
    type Narrow = Avx2;
    #[inline(always)]
    unsafe fn zero() -> __m512d {
        unsafe { _mm512_setzero_pd() }
    }
    #[inline(always)]
    unsafe fn neg_inf() -> __m512d {
        unsafe { _mm512_set1_pd(f64::NEG_INFINITY) }
    }
    #[inline(always)]
    unsafe fn splat(x: f64) -> __m512d {
        unsafe { _mm512_set1_pd(x) }
    }
    #[inline(always)]
    unsafe fn mask(n: usize) -> __mmask8 {
        ((1u32 << n) - 1) as __mmask8
    }
    #[inline(always)]
    unsafe fn load(p: *const f64) -> __m512d {
        unsafe { _mm512_loadu_pd(p) }
    }
    #[inline(always)]
    unsafe fn load_part(p: *const f64, m: __mmask8) -> __m512d {
        unsafe { _mm512_maskz_loadu_pd(m, p) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f64, v: __m512d) {
        unsafe { _mm512_storeu_pd(p, v) }
    }
    #[inline(always)]
    unsafe fn store_part(p: *mut f64, v: __m512d, m: __mmask8, _n: usize) {
        unsafe { _mm512_mask_storeu_pd(p, m, v) }
    }
    const RANGE_STORES: bool = true;
    #[inline(always)]
    unsafe fn store_range(p: *mut f64, v: __m512d, lo: usize, hi: usize) {
        let m = (((1u32 << hi) - 1) & !((1u32 << lo) - 1)) as __mmask8;
        unsafe { _mm512_mask_storeu_pd(p, m, v) }
    }
    #[inline(always)]
    unsafe fn equal_bits(v: __m512d, t: f64, m: __mmask8) -> u64 {
        (unsafe { _mm512_mask_cmpeq_pd_mask(m, v, _mm512_set1_pd(t)) }) as u64
    }
    #[inline(always)]
    unsafe fn fma(a: __m512d, b: __m512d, c: __m512d) -> __m512d {
        unsafe { _mm512_fmadd_pd(a, b, c) }
    }
    #[inline(always)]
    unsafe fn max(a: __m512d, b: __m512d) -> __m512d {
        unsafe { _mm512_max_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn abs(a: __m512d) -> __m512d {
        unsafe { _mm512_abs_pd(a) }
    }
    #[inline(always)]
    unsafe fn reduce_max(v: __m512d, m: __mmask8) -> f64 {
        // Not `_mm512_mask_reduce_max_pd`: it fills the masked-off lanes with the lowest
        // finite value, not minus infinity, so lanes all minus infinity reduced to it.
        unsafe { _mm512_reduce_max_pd(<Self as Isa<f64>>::load_part_from(v, m)) }
    }
    #[inline(always)]
    unsafe fn load_part_from(v: __m512d, m: __mmask8) -> __m512d {
        unsafe { _mm512_mask_mov_pd(_mm512_set1_pd(f64::NEG_INFINITY), m, v) }
    }
    #[inline(always)]
    unsafe fn fma1(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
    #[inline(always)]
    unsafe fn max1(a: f64, b: f64) -> f64 {
        if a >= b { a } else { b }
    }
}

/// Lane masks for AVX2 masked loads: a window of 8 (or 4) lanes starting at `8 - n`.
static MASK32: [i32; 16] = [-1, -1, -1, -1, -1, -1, -1, -1, 0, 0, 0, 0, 0, 0, 0, 0];
static MASK64: [i64; 8] = [-1, -1, -1, -1, 0, 0, 0, 0];

impl Isa<f32> for Avx2 {
    type V = __m256;
    type M = __m256i;
    const LANES: usize = 8;
    const BLOCK: usize = 8;
    const MERGED: usize = 2;
    const MASK_COMPARES: bool = true;
    const OVERREAD: usize = 0;
    type Exact = Self;
    type Narrow = Self;
    #[inline(always)]
    unsafe fn zero() -> __m256 {
        unsafe { _mm256_setzero_ps() }
    }
    #[inline(always)]
    unsafe fn neg_inf() -> __m256 {
        unsafe { _mm256_set1_ps(f32::NEG_INFINITY) }
    }
    #[inline(always)]
    unsafe fn splat(x: f32) -> __m256 {
        unsafe { _mm256_set1_ps(x) }
    }
    #[inline(always)]
    unsafe fn mask(n: usize) -> __m256i {
        // SAFETY: 1 <= n <= 8, so the 8 lanes read lie within MASK32.
        unsafe { _mm256_loadu_si256(MASK32.as_ptr().add(8 - n).cast()) }
    }
    #[inline(always)]
    unsafe fn load(p: *const f32) -> __m256 {
        unsafe { _mm256_loadu_ps(p) }
    }
    #[inline(always)]
    unsafe fn load_part(p: *const f32, m: __m256i) -> __m256 {
        unsafe { _mm256_maskload_ps(p, m) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f32, v: __m256) {
        unsafe { _mm256_storeu_ps(p, v) }
    }
    #[inline(always)]
    unsafe fn store_part(p: *mut f32, v: __m256, _m: __m256i, n: usize) {
        // Masked stores (vmaskmovps) are microcoded and very slow on AMD CPUs, and a
        // variable-length copy calls the C library: store 4, 2 and 1 lanes as `n`'s bits
        // say (the branches are predictable: a kernel call has one tail length).
        unsafe {
            if n == 8 {
                _mm256_storeu_ps(p, v);
                return;
            }
            let mut p = p;
            let mut x = _mm256_castps256_ps128(v);
            if n & 4 != 0 {
                _mm_storeu_ps(p, x);
                p = p.add(4);
                x = _mm256_extractf128_ps::<1>(v);
            }
            if n & 2 != 0 {
                _mm_storel_pd(p.cast(), _mm_castps_pd(x));
                p = p.add(2);
                x = _mm_movehl_ps(x, x);
            }
            if n & 1 != 0 {
                _mm_store_ss(p, x);
            }
        }
    }
    #[inline(always)]
    unsafe fn equal_bits(v: __m256, t: f32, m: __m256i) -> u64 {
        let bits = unsafe {
            let c = _mm256_cmp_ps::<_CMP_EQ_OQ>(v, _mm256_set1_ps(t));
            _mm256_movemask_ps(c) & _mm256_movemask_ps(_mm256_castsi256_ps(m))
        };
        bits as u32 as u64
    }
    #[inline(always)]
    unsafe fn fma(a: __m256, b: __m256, c: __m256) -> __m256 {
        unsafe { _mm256_fmadd_ps(a, b, c) }
    }
    #[inline(always)]
    unsafe fn max(a: __m256, b: __m256) -> __m256 {
        unsafe { _mm256_max_ps(a, b) }
    }
    #[inline(always)]
    unsafe fn abs(a: __m256) -> __m256 {
        unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), a) }
    }
    #[inline(always)]
    unsafe fn reduce_max(v: __m256, m: __m256i) -> f32 {
        unsafe {
            let v = _mm256_blendv_ps(_mm256_set1_ps(f32::NEG_INFINITY), v, _mm256_castsi256_ps(m));
            let h = _mm_max_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
            let h = _mm_max_ps(h, _mm_movehl_ps(h, h));
            let h = _mm_max_ss(h, _mm_shuffle_ps(h, h, 1));
            _mm_cvtss_f32(h)
        }
    }
    #[inline(always)]
    unsafe fn load_part_from(v: __m256, m: __m256i) -> __m256 {
        unsafe { _mm256_blendv_ps(_mm256_set1_ps(f32::NEG_INFINITY), v, _mm256_castsi256_ps(m)) }
    }
    #[inline(always)]
    unsafe fn fma1(a: f32, b: f32, c: f32) -> f32 {
        a.mul_add(b, c)
    }
    #[inline(always)]
    unsafe fn max1(a: f32, b: f32) -> f32 {
        if a >= b { a } else { b }
    }
}

impl Isa<f64> for Avx2 {
    type V = __m256d;
    type M = __m256i;
    const LANES: usize = 4;
    const BLOCK: usize = 6;
    const MERGED: usize = 2;
    const MASK_COMPARES: bool = true;
    const OVERREAD: usize = 0;
    type Exact = Self;
    type Narrow = Self;
    #[inline(always)]
    unsafe fn zero() -> __m256d {
        unsafe { _mm256_setzero_pd() }
    }
    #[inline(always)]
    unsafe fn neg_inf() -> __m256d {
        unsafe { _mm256_set1_pd(f64::NEG_INFINITY) }
    }
    #[inline(always)]
    unsafe fn splat(x: f64) -> __m256d {
        unsafe { _mm256_set1_pd(x) }
    }
    #[inline(always)]
    unsafe fn mask(n: usize) -> __m256i {
        // SAFETY: 1 <= n <= 4, so the 4 lanes read lie within MASK64.
        unsafe { _mm256_loadu_si256(MASK64.as_ptr().add(4 - n).cast()) }
    }
    #[inline(always)]
    unsafe fn load(p: *const f64) -> __m256d {
        unsafe { _mm256_loadu_pd(p) }
    }
    #[inline(always)]
    unsafe fn load_part(p: *const f64, m: __m256i) -> __m256d {
        unsafe { _mm256_maskload_pd(p, m) }
    }
    #[inline(always)]
    unsafe fn store(p: *mut f64, v: __m256d) {
        unsafe { _mm256_storeu_pd(p, v) }
    }
    #[inline(always)]
    unsafe fn store_part(p: *mut f64, v: __m256d, _m: __m256i, n: usize) {
        // See the f32 instance.
        unsafe {
            if n == 4 {
                _mm256_storeu_pd(p, v);
                return;
            }
            let mut p = p;
            let mut x = _mm256_castpd256_pd128(v);
            if n & 2 != 0 {
                _mm_storeu_pd(p, x);
                p = p.add(2);
                x = _mm256_extractf128_pd::<1>(v);
            }
            if n & 1 != 0 {
                _mm_store_sd(p, x);
            }
        }
    }
    #[inline(always)]
    unsafe fn equal_bits(v: __m256d, t: f64, m: __m256i) -> u64 {
        let bits = unsafe {
            let c = _mm256_cmp_pd::<_CMP_EQ_OQ>(v, _mm256_set1_pd(t));
            _mm256_movemask_pd(c) & _mm256_movemask_pd(_mm256_castsi256_pd(m))
        };
        bits as u32 as u64
    }
    #[inline(always)]
    unsafe fn fma(a: __m256d, b: __m256d, c: __m256d) -> __m256d {
        unsafe { _mm256_fmadd_pd(a, b, c) }
    }
    #[inline(always)]
    unsafe fn max(a: __m256d, b: __m256d) -> __m256d {
        unsafe { _mm256_max_pd(a, b) }
    }
    #[inline(always)]
    unsafe fn abs(a: __m256d) -> __m256d {
        unsafe { _mm256_andnot_pd(_mm256_set1_pd(-0.0), a) }
    }
    #[inline(always)]
    unsafe fn reduce_max(v: __m256d, m: __m256i) -> f64 {
        unsafe {
            let v = _mm256_blendv_pd(_mm256_set1_pd(f64::NEG_INFINITY), v, _mm256_castsi256_pd(m));
            let h = _mm_max_pd(_mm256_castpd256_pd128(v), _mm256_extractf128_pd(v, 1));
            let h = _mm_max_sd(h, _mm_unpackhi_pd(h, h));
            _mm_cvtsd_f64(h)
        }
    }
    #[inline(always)]
    unsafe fn load_part_from(v: __m256d, m: __m256i) -> __m256d {
        unsafe { _mm256_blendv_pd(_mm256_set1_pd(f64::NEG_INFINITY), v, _mm256_castsi256_pd(m)) }
    }
    #[inline(always)]
    unsafe fn fma1(a: f64, b: f64, c: f64) -> f64 {
        a.mul_add(b, c)
    }
    #[inline(always)]
    unsafe fn max1(a: f64, b: f64) -> f64 {
        if a >= b { a } else { b }
    }
}
