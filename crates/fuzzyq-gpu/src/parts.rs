//! How `V` and the other per-core buffers are cut into parts that each fit one storage
//! binding.
//!
//! `V` is laid out block-major in the contraction order: core `c_0 R_0 + r`, where `c_0` is the
//! first block's core and `r < R_0` runs over the later blocks' cores. A *slab* is the `R_0`
//! cores of one `c_0`; a part is a run of `per` consecutive slabs (the last part may hold
//! fewer), so every index a shader computes within a part fits `u32` however many cores the
//! grid has. One binding holds at most 2 GiB through wgpu (`i32::MAX` bytes, on every
//! backend): three point masses on the paper's cores (`V` 33 GB, a slab 738 MB) take 23 parts
//! of 2 slabs. A stage's output over one binding is cut the same way, in units of the values
//! one column of the next stage reads (`sweeps.rs`).
//!
//! The passes that write per-core values run a part at a time (a batch of the last stage never
//! straddles two parts); the two that read `V` at other cores (the first stage of a full backup
//! and policy evaluation) bind every part of it at once and pick the part from `c_0`
//! ([`Parts::reader`]).

use core::ops::Range;

use crate::error::GpuError;

/// [`Parts::reader`] of a `V` in one part: the same for every problem (`R_0` from the
/// dispatch's parameters), so the kernels that read it compile once per GPU.
pub(crate) const ONE_PART: &str = "@group(1) @binding(0) var<storage, read> vp0: array<f32>;
fn v_at(c0: u32, r: u32) -> f32 {
    return vp0[c0 * blk(0u).z + r];
}
";

/// The parts of a run's per-core buffers.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Parts {
    /// Cores per slab (`R_0`).
    pub slab: u64,
    /// Slabs (the first block's cores).
    pub slabs: u64,
    /// Slabs per part.
    pub per: u64,
}

impl Parts {
    /// Parts over `slabs` slabs of `slab` `f32` values: of about `wish` bytes (whole slabs, at
    /// least one), larger where `max_parts` parts would not hold them, each within one binding
    /// of `max_bytes`. Refused where one slab exceeds a binding, or `max_parts` of a binding
    /// each do not hold `V`.
    pub(crate) fn new(
        slabs: u64,
        slab: u64,
        max_bytes: u64,
        wish: u64,
        max_parts: u64,
    ) -> Result<Self, GpuError> {
        let slab_bytes = 4 * slab;
        if slab_bytes > max_bytes {
            return Err(GpuError::over_binding(
                "one slab of V",
                slab_bytes,
                max_bytes,
            ));
        }
        let fit = max_bytes / slab_bytes;
        let fewest = slabs.div_ceil(max_parts.max(1));
        let per = (wish / slab_bytes)
            .max(fewest)
            .min(fit)
            .clamp(1, slabs.max(1));
        let parts = Self { slab, slabs, per };
        if parts.count() as u64 > max_parts {
            return Err(GpuError::TooManyParts {
                parts: parts.count(),
                limit: max_parts,
            });
        }
        Ok(parts)
    }

    /// How many parts.
    pub(crate) fn count(&self) -> usize {
        self.slabs.div_ceil(self.per) as usize
    }

    /// The cores of part `k` (global indices).
    pub(crate) fn cores(&self, k: usize) -> Range<u64> {
        let first = k as u64 * self.per;
        let end = (first + self.per).min(self.slabs);
        first * self.slab..end * self.slab
    }

    /// Cores of part `k`.
    pub(crate) fn len(&self, k: usize) -> u64 {
        let r = self.cores(k);
        r.end - r.start
    }

    /// Cores of the largest part (the first: only the last may hold fewer slabs).
    pub(crate) fn largest(&self) -> u64 {
        self.len(0)
    }

    /// Per-core `f32` or `u32` buffers, one zeroed buffer per part.
    pub(crate) fn zeroed(&self, gpu: &crate::context::Context, label: &str) -> Vec<wgpu::Buffer> {
        (0..self.count())
            .map(|k| crate::buffers::zeroed(gpu, label, 4 * self.len(k)))
            .collect()
    }

    /// The part holding core `core`.
    pub(crate) fn of_core(&self, core: u64) -> usize {
        (core / self.slab / self.per) as usize
    }

    /// The first slab of part `k`.
    pub(crate) fn first_slab(&self, k: usize) -> u64 {
        k as u64 * self.per
    }

    /// Words of a part's goal bits (a part's bits start at a word: `goal_lo` in `block.wgsl`).
    pub(crate) fn goal_words(&self) -> u64 {
        (self.per * self.slab).div_ceil(32)
    }

    /// `data` (`width` values per core) cut into the parts.
    pub(crate) fn split<'a, T>(
        &self,
        data: &'a [T],
        width: usize,
    ) -> impl Iterator<Item = &'a [T]> {
        (0..self.count()).map(move |k| {
            let r = self.cores(k);
            &data[r.start as usize * width..r.end as usize * width]
        })
    }

    /// WGSL declaring the parts of the `V` a kernel reads as bindings `vp0..` of group 1,
    /// and `v_at(c0, r)`: `V` at core `c0 R_0 + r` ([`ONE_PART`] where there is one).
    pub(crate) fn reader(&self) -> String {
        if self.count() == 1 {
            return ONE_PART.to_string();
        }
        self.declare(0, "vp", "read") + &self.getter("v_at", "vp")
    }

    /// WGSL declaring the parts as bindings `first..` of group 1 named `{name}0..`
    /// (`access`: `read` or `read_write`).
    pub(crate) fn declare(&self, first: usize, name: &str, access: &str) -> String {
        (0..self.count())
            .map(|k| {
                let b = first + k;
                format!("@group(1) @binding({b}) var<storage, {access}> {name}{k}: array<f32>;\n")
            })
            .collect()
    }

    /// `switch` arms over the parts, the last one `default`: `body(k)` per part `k`.
    fn arms(&self, body: impl Fn(usize) -> String) -> String {
        (0..self.count())
            .map(|k| {
                let case = if k + 1 == self.count() {
                    "default".to_string()
                } else {
                    format!("case {k}u")
                };
                format!("        {case}: {{ {} }}\n", body(k))
            })
            .collect()
    }

    /// WGSL of `fn {f}(u: u32, i: u32) -> f32`: element `i` of slab (unit) `u` of the parts
    /// [`Self::declare`]d as `{name}`.
    pub(crate) fn getter(&self, f: &str, name: &str) -> String {
        format!(
            "fn {f}(u: u32, i: u32) -> f32 {{\n    let j = (u % {per}u) * {slab}u + i;\n    \
             switch u / {per}u {{\n{arms}    }}\n}}\n",
            per = self.per,
            slab = self.slab,
            arms = self.arms(|k| format!("return {name}{k}[j];")),
        )
    }

    /// WGSL of `fn {f}(o: u32, x: f32)`: element `o`, counted over every part in order, of
    /// the parts [`Self::declare`]d as `{name}` set to `x`.
    pub(crate) fn setter(&self, f: &str, name: &str) -> String {
        format!(
            "fn {f}(o: u32, x: f32) {{\n    let j = o % {span}u;\n    \
             switch o / {span}u {{\n{arms}    }}\n}}\n",
            span = self.per * self.slab,
            arms = self.arms(|k| format!("{name}{k}[j] = x;")),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parts_cover_every_core_once_within_the_limit() {
        for (slabs, slab, max) in [
            (7u64, 10u64, 80u64),
            (7, 10, 280),
            (7, 10, 1 << 20),
            (1, 3, 12),
        ] {
            let p = Parts::new(slabs, slab, max, max, 100).unwrap();
            let mut next = 0;
            for k in 0..p.count() {
                let r = p.cores(k);
                assert_eq!(r.start, next);
                assert!(4 * p.len(k) <= max);
                assert_eq!(p.of_core(r.start), k);
                assert_eq!(p.of_core(r.end - 1), k);
                assert_eq!(p.first_slab(k) * slab, r.start);
                next = r.end;
            }
            assert_eq!(next, slabs * slab);
        }
        assert_eq!(Parts::new(7, 10, 280, 120, 100).unwrap().count(), 3);
        // The wish gives way to the bindings a kernel may hold, and to one binding's size.
        assert_eq!(Parts::new(7, 10, 280, 1, 100).unwrap().count(), 7);
        assert_eq!(Parts::new(7, 10, 280, 1, 4).unwrap().per, 2);
        assert_eq!(Parts::new(7, 10, 80, 1 << 20, 100).unwrap().per, 2);
        let e = Parts::new(7, 10, 39, 39, 100).unwrap_err().to_string();
        assert!(e.starts_with("one slab of V needs 40 bytes"), "{e}");
        let e = Parts::new(7, 10, 80, 80, 3).unwrap_err().to_string();
        assert!(e.starts_with("V in 4 parts"), "{e}");
    }

    /// wgpu's largest storage binding on every backend: `i32::MAX` bytes, in whole `f32`s.
    const WGPU_MAX_BINDING: u64 = (1 << 31) - 4;

    #[test]
    fn the_papers_three_point_masses_take_23_parts_of_two_slabs() {
        let max = WGPU_MAX_BINDING;
        let p = Parts::new(45, 45u64.pow(5), max, max, 100).unwrap();
        assert_eq!((p.count(), p.per), (23, 2));
        // Every index within a part fits u32.
        assert!(p.per * p.slab < 1 << 32);
    }

    #[test]
    fn the_wgsl_of_parts_names_each_part_once() {
        let p = Parts::new(5, 10, 80, 80, 100).unwrap();
        assert_eq!((p.count(), p.per), (3, 2));
        let d = p.declare(4, "dp", "read_write");
        assert_eq!(d.lines().count(), 3);
        assert!(d.contains("@group(1) @binding(6) var<storage, read_write> dp2: array<f32>;"));
        let g = p.getter("s_at", "sp");
        assert!(g.contains("let j = (u % 2u) * 10u + i;"), "{g}");
        assert!(
            g.contains("case 1u: { return sp1[j]; }") && g.contains("default: { return sp2[j]; }")
        );
        let s = p.setter("put", "dp");
        assert!(
            s.contains("let j = o % 20u;") && s.contains("switch o / 20u"),
            "{s}"
        );
        assert!(s.contains("case 0u: { dp0[j] = x; }") && s.contains("default: { dp2[j] = x; }"));
    }
}
