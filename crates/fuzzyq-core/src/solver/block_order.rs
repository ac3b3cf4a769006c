//! Orders of the cores on the block path (`block.rs`): the internal order the stages run in
//! (the first contracted block slowest, its cores' slabs contiguous) against the grid's
//! row-major order, the conversions between them, and the cores' states in internal order.
//! Everything here steps the block cores like an odometer instead of dividing per core.

use super::*;

/// Calls `f(i, g)` for every index `i` of the product of `tables`' cores (the first table
/// slowest) with `g` the sum of their grid offsets, stepping the cores like an odometer (no
/// divisions).
fn odometer<T>(tables: &[BlockTable<T>], mut f: impl FnMut(usize, usize)) {
    let nb = tables.len();
    let mut digit = vec![0usize; nb];
    let mut g: usize = tables.iter().map(|t| t.grid_offset[0]).sum();
    let n: usize = tables.iter().map(|t| t.n_cores).product();
    for i in 0..n {
        f(i, g);
        for b in (0..nb).rev() {
            let t = &tables[b];
            g -= t.grid_offset[digit[b]];
            digit[b] += 1;
            if digit[b] < t.n_cores {
                g += t.grid_offset[digit[b]];
                break;
            }
            digit[b] = 0;
            g += t.grid_offset[0];
        }
    }
}

impl<T: Real> BlockOperator<T> {
    /// Calls `f(internal, grid)` for every core in internal order, stepping the block cores
    /// like an odometer (no divisions).
    pub(in crate::solver) fn for_each_grid_index(&self, f: impl FnMut(usize, usize)) {
        odometer(&self.tables, f);
    }

    /// `v` from internal to grid order (`to_grid`), or back.
    ///
    /// Internal index `c0 * slab_len + j` (`c0` a core of the first contracted block, `j`
    /// the odometer over the others) is grid index `grid_offset[c0] + rest[j]`. The first
    /// contracted block is the grid's *fastest* variables, so the conversion is a transpose
    /// (the robots': 6,137 x 6,137): stepped through in square tiles, whose reads and writes
    /// each stay within a few cache lines, instead of one strided write per core. The
    /// gather (to internal order) runs on every thread, a band of first-block cores each; so
    /// does the scatter (to grid order) where each grid row holds one `j` (the usual layout),
    /// a band of rows each.
    pub(in crate::solver) fn reorder<U: Copy + Default + Send + Sync>(
        &self,
        v: &[U],
        to_grid: bool,
    ) -> Vec<U> {
        /// Side of a tile.
        const TILE: usize = 64;
        let slab_len = self.slab_len();
        let (first, rest) = self.tables.split_first().expect("at least one block");
        let g0 = &first.grid_offset;
        let mut g_rest = Vec::with_capacity(slab_len);
        odometer(rest, |_, g| g_rest.push(g));
        let mut out = vec![U::default(); v.len()];
        let tiles = |n: usize| (0..n).step_by(TILE).map(move |t| t..n.min(t + TILE));
        let n0 = first.n_cores;
        // The usual layout (the robots', the point masses'): the first block's offsets lie
        // in `0..n0` and the rest's are `j * n0`, so grid row `j` is `out[j n0..(j + 1) n0]`
        // and bands of rows fill on every thread.
        let rows_apart =
            g0.iter().all(|&g| g < n0) && g_rest.iter().enumerate().all(|(j, &g)| g == j * n0);
        if to_grid && rows_apart && n0 > 0 {
            super::par::for_each_chunk_mut(
                &mut out,
                TILE * n0,
                || (),
                |_, t, band| {
                    let js = t * TILE..t * TILE + band.len() / n0;
                    for c0s in tiles(n0) {
                        for (j, row) in js.clone().zip(band.chunks_mut(n0)) {
                            for c0 in c0s.clone() {
                                row[g0[c0]] = v[c0 * slab_len + j];
                            }
                        }
                    }
                },
            );
        } else if to_grid {
            for band in tiles(first.n_cores) {
                for js in tiles(slab_len) {
                    for c0 in band.clone() {
                        let src = &v[c0 * slab_len..(c0 + 1) * slab_len];
                        for j in js.clone() {
                            out[g0[c0] + g_rest[j]] = src[j];
                        }
                    }
                }
            }
        } else {
            super::par::for_each_chunk_mut(
                &mut out,
                TILE * slab_len,
                || (),
                |_, t, band| {
                    for js in tiles(slab_len) {
                        for (k, row) in band.chunks_mut(slab_len).enumerate() {
                            let g = g0[t * TILE + k];
                            for j in js.clone() {
                                row[j] = v[g + g_rest[j]];
                            }
                        }
                    }
                },
            );
        }
        out
    }

    /// Every block core's coordinates on its block's variables (`n_cores x dims.len()` per
    /// block), read from `state_of(g, x)`, the state of grid core `g`.
    pub(in crate::solver) fn block_coords(
        &self,
        n_dims: usize,
        mut state_of: impl FnMut(usize, &mut [T]),
    ) -> Vec<Vec<T>> {
        let mut x = vec![T::ZERO; n_dims];
        self.tables
            .iter()
            .map(|t| {
                let mut coords = Vec::with_capacity(t.n_cores * t.dims.len());
                for &g in &t.grid_offset {
                    state_of(g, &mut x);
                    coords.extend(t.dims.iter().map(|&d| x[d]));
                }
                coords
            })
            .collect()
    }

    /// Calls `f(i, x)` with the state `x` of every internal core `i` in `range`, in order,
    /// stepping the block cores like an odometer and copying each new block core's
    /// coordinates (`coords` from [`Self::block_coords`]): no division per core.
    pub(in crate::solver) fn for_each_core_state(
        &self,
        coords: &[Vec<T>],
        range: core::ops::Range<usize>,
        x: &mut [T],
        mut f: impl FnMut(usize, &[T]),
    ) {
        let place = |b: usize, c: usize, x: &mut [T]| {
            let dims = &self.tables[b].dims;
            for (&d, &v) in dims.iter().zip(&coords[b][c * dims.len()..]) {
                x[d] = v;
            }
        };
        let mut digit: Vec<usize> = (0..self.tables.len())
            .map(|b| (range.start / self.r_len[b]) % self.tables[b].n_cores)
            .collect();
        for (b, &c) in digit.iter().enumerate() {
            place(b, c, x);
        }
        for i in range {
            f(i, x);
            for b in (0..digit.len()).rev() {
                digit[b] += 1;
                let carry = digit[b] == self.tables[b].n_cores;
                if carry {
                    digit[b] = 0;
                }
                place(b, digit[b], x);
                if !carry {
                    break;
                }
            }
        }
    }

    /// Internal index (contraction order, first block slowest) -> row-major grid index.
    pub(in crate::solver) fn to_grid_index(&self, internal: usize) -> usize {
        let mut g = 0;
        for (b, t) in self.tables.iter().enumerate() {
            let c = (internal / self.r_len[b]) % t.n_cores;
            g += t.grid_offset[c];
        }
        g
    }
}
