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

/// Calls `f(i, x)` for every index `i` in `range` of the product of the blocks' points (the
/// first block slowest), `x` holding point `i`'s coordinates. Block `b` is `points[b] = (dims,
/// coords)`: its points' coordinates on the state variables `dims`, `dims.len()` per point.
/// Steps the points like an odometer, copying a block's coordinates when its point changes.
fn for_each_point<T: Copy>(
    points: &[(&[usize], &[T])],
    range: core::ops::Range<usize>,
    x: &mut [T],
    mut f: impl FnMut(usize, &[T]),
) {
    // Per block: its points (counted once: no division per point).
    let counts: Vec<usize> = points.iter().map(|(d, c)| c.len() / d.len()).collect();
    let count = |b: usize| counts[b];
    let place = |b: usize, p: usize, x: &mut [T]| {
        let (dims, coords) = points[b];
        for (&d, &v) in dims.iter().zip(&coords[p * dims.len()..]) {
            x[d] = v;
        }
    };
    // Per block: the product of the later blocks' point counts.
    let mut later = vec![1usize; points.len()];
    for b in (0..points.len().saturating_sub(1)).rev() {
        later[b] = later[b + 1] * count(b + 1);
    }
    let mut digit: Vec<usize> = (0..points.len())
        .map(|b| (range.start / later[b]) % count(b))
        .collect();
    for (b, &p) in digit.iter().enumerate() {
        place(b, p, x);
    }
    for i in range {
        f(i, x);
        for b in (0..digit.len()).rev() {
            digit[b] += 1;
            let carry = digit[b] == count(b);
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

/// One block's cores grouped by the state variables a function reads
/// ([`BlockOperator::core_classes`]).
pub(in crate::solver) struct CoreClasses<T> {
    /// Each block core's class.
    class: Vec<u32>,
    /// Each class's first core's coordinates on the block's variables.
    coords: Vec<T>,
    /// Number of classes.
    n_classes: usize,
}

impl<T> CoreClasses<T> {
    /// Number of classes.
    pub(in crate::solver) fn n_classes(&self) -> usize {
        self.n_classes
    }
}

/// The long side of the tiles a reordering steps through: the values it reads or writes
/// contiguously, and the slabs or rows of a band one thread fills.
const TILE: usize = 64;

/// The short side of the tiles: the values taken a stride apart before the next contiguous
/// one. 8 against 64 (square tiles) makes the robots' reorderings 1.7-1.8 times faster
/// (`cargo bench -p fuzzyq-benches --bench orders`, Zen 4).
const NARROW: usize = 8;

/// `range` in runs of at most `size`.
fn tiles(
    range: core::ops::Range<usize>,
    size: usize,
) -> impl Iterator<Item = core::ops::Range<usize>> + Clone {
    let end = range.end;
    range.step_by(size).map(move |t| t..end.min(t + size))
}

impl<T: Real> BlockOperator<T> {
    /// Calls `f(internal, grid)` for every core in internal order, stepping the block cores
    /// like an odometer (no divisions).
    pub(in crate::solver) fn for_each_grid_index(&self, f: impl FnMut(usize, usize)) {
        odometer(&self.tables, f);
    }

    /// `v` from internal to grid order (`to_grid`), or back.
    pub(in crate::solver) fn reorder<U: bytemuck::Pod + Default + Send + Sync>(
        &self,
        v: &[U],
        to_grid: bool,
    ) -> Vec<U> {
        let mut out = vec![U::default(); v.len()];
        if to_grid {
            self.slab_placer().place(0, v, &mut out);
        } else {
            self.gather(v, &mut out);
        }
        out
    }

    /// The grid indices of the cores of a slab, `g_rest[j]` for the core `j` of the later
    /// blocks (grid index `grid_offset[c0] + g_rest[j]`), and the first block's table.
    fn slab_offsets(&self) -> (&BlockTable<T>, Vec<usize>) {
        let (first, rest) = self.tables.split_first().expect("at least one block");
        let mut g_rest = Vec::with_capacity(self.slab_len());
        odometer(rest, |_, g| g_rest.push(g));
        (first, g_rest)
    }

    /// Where whole slabs' values go in grid order, for every piece of a result
    /// ([`SlabPlacer::place`]).
    pub(in crate::solver) fn slab_placer(&self) -> SlabPlacer<'_, T> {
        let first = &self.tables[0];
        let n0 = first.n_cores;
        // The usual layout (the robots'): the first block's offsets lie in `0..n0` and the
        // rest's are `j * n0`, so grid row `j` is `out[j n0..(j + 1) n0]`.
        let mut rows_apart = first.grid_offset.iter().all(|&g| g < n0);
        if rows_apart {
            odometer(&self.tables[1..], |j, g| rows_apart &= g == j * n0);
        }
        SlabPlacer {
            op: self,
            g_rest: if rows_apart {
                Vec::new()
            } else {
                self.slab_offsets().1
            },
        }
    }

    /// `v` (grid order) in internal order in `out`: on every thread, a band of first-block
    /// cores each, in tiles ([`SlabPlacer::place`]).
    fn gather<U: Copy + Send + Sync>(&self, v: &[U], out: &mut [U]) {
        let slab_len = self.slab_len();
        let (first, g_rest) = self.slab_offsets();
        let g0 = &first.grid_offset;
        super::par::for_each_chunk_mut(
            out,
            TILE * slab_len,
            || (),
            |_, t, band| {
                for js in tiles(0..slab_len, NARROW) {
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
        f: impl FnMut(usize, &[T]),
    ) {
        self.for_each_point(coords.iter().map(|c| &c[..]), range, x, f);
    }

    /// The block cores grouped by the state variables `reads` keeps: per block, each block
    /// core's class (block cores that agree on every kept variable of their block share one,
    /// numbered in order of first appearance) and the coordinates (`coords` from
    /// [`Self::block_coords`]) of each class's first core. A function of the kept variables
    /// alone takes one value per product of classes ([`Self::for_each_class_state`]), which
    /// [`Self::spread`] copies to every core.
    pub(in crate::solver) fn core_classes(
        &self,
        coords: &[Vec<T>],
        reads: impl Fn(usize) -> bool,
    ) -> Vec<CoreClasses<T>> {
        self.tables
            .iter()
            .zip(coords)
            .map(|(t, coords)| {
                let kept: Vec<usize> = (0..t.dims.len()).filter(|&k| reads(t.dims[k])).collect();
                let mut first = std::collections::BTreeMap::new();
                let mut classes = CoreClasses {
                    class: Vec::with_capacity(t.n_cores),
                    coords: Vec::new(),
                    n_classes: 0,
                };
                for point in coords.chunks_exact(t.dims.len()) {
                    let key: Vec<u64> = kept.iter().map(|&k| point[k].to_f64().to_bits()).collect();
                    let n = first.len() as u32;
                    let class = *first.entry(key).or_insert_with(|| {
                        classes.coords.extend_from_slice(point);
                        n
                    });
                    classes.class.push(class);
                }
                classes.n_classes = first.len();
                classes
            })
            .collect()
    }

    /// Calls `f(k, x)` for every product `k` in `range` of [`Self::core_classes`]' classes
    /// (the first block slowest, as the cores), `x` the state of its first core.
    pub(in crate::solver) fn for_each_class_state(
        &self,
        classes: &[CoreClasses<T>],
        range: core::ops::Range<usize>,
        x: &mut [T],
        f: impl FnMut(usize, &[T]),
    ) {
        self.for_each_point(classes.iter().map(|c| &c.coords[..]), range, x, f);
    }

    /// [`for_each_point`] over the points of each block whose coordinates on the block's
    /// variables `coords` gives.
    fn for_each_point<'c>(
        &self,
        coords: impl Iterator<Item = &'c [T]>,
        range: core::ops::Range<usize>,
        x: &mut [T],
        f: impl FnMut(usize, &[T]),
    ) {
        let points: Vec<_> = self
            .tables
            .iter()
            .map(|t| &t.dims[..])
            .zip(coords)
            .collect();
        for_each_point(&points, range, x, f);
    }

    /// `out[i] = by_class[k]` for every core `i` (internal order), `k` its product of
    /// [`Self::core_classes`]' classes: on every thread, whole rows of the last block's cores
    /// at a time, one division per row.
    pub(in crate::solver) fn spread<U: Copy + Send + Sync>(
        &self,
        classes: &[CoreClasses<T>],
        by_class: &[U],
        out: &mut [U],
    ) {
        // Per block: each block core's offset in `by_class` (its class times the product of
        // the later blocks' class counts).
        let mut stride = 1;
        let mut offsets: Vec<Vec<usize>> = classes
            .iter()
            .rev()
            .map(|c| {
                let o = c.class.iter().map(|&k| k as usize * stride).collect();
                stride *= c.n_classes();
                o
            })
            .collect();
        offsets.reverse();
        let (last, rest) = offsets.split_last().expect("at least one block");
        let row = last.len();
        let rows_per_task = (1usize << 16).div_ceil(row);
        super::par::for_each_chunk_mut(
            out,
            rows_per_task * row,
            || (),
            |_, t, chunk| {
                for (r, out) in chunk.chunks_mut(row).enumerate() {
                    let r = t * rows_per_task + r;
                    let base: usize = rest
                        .iter()
                        .zip(&self.r_len)
                        .map(|(o, &len)| o[(r / (len / row)) % o.len()])
                        .sum();
                    for (o, &k) in out.iter_mut().zip(last) {
                        *o = by_class[base + k];
                    }
                }
            },
        );
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

/// Where whole slabs' values go in grid order ([`BlockOperator::slab_placer`]).
pub(in crate::solver) struct SlabPlacer<'b, T: 'static> {
    op: &'b BlockOperator<T>,
    /// The grid offsets of a slab's cores (`g_rest[j]` for the core `j` of the later
    /// blocks); empty where grid row `j` is `out[j n0..(j + 1) n0]`.
    g_rest: Vec<usize>,
}

impl<T: Real> SlabPlacer<'_, T> {
    /// Places `piece`, the values of the whole slabs from `first_slab` on in internal order,
    /// at their grid indices in `out` (every core's); the other values of `out` are left.
    ///
    /// Internal index `c0 * slab_len + j` (`c0` a core of the first contracted block, `j`
    /// the odometer over the others) is grid index `grid_offset[c0] + rest[j]`. The first
    /// contracted block is often the grid's *fastest* variables, so the conversion is a
    /// transpose (the robots': 6,137 x 6,137): stepped through in tiles whose reads and
    /// writes each stay within a few cache lines, instead of one strided write per core.
    /// Where each grid row holds one `j` (the usual layout) bands of rows fill on every
    /// thread; elsewhere (the point masses') runs of a slab's cores do, each value stored
    /// atomically ([`scatter`]), as the runs' grid indices interleave. A backend that holds
    /// `V` elsewhere hands it over a few slabs at a time, so the caller holds one copy of it
    /// (`sweeps::grid_order`); the slabs' grid offsets are found once for all its pieces (for
    /// three point masses on the paper's cores, 184.5M of them, 1.5 GB).
    ///
    /// # Panics
    /// If `piece` is not whole slabs within the grid's.
    pub(in crate::solver) fn place<U: bytemuck::Pod + Send + Sync>(
        &self,
        first_slab: usize,
        piece: &[U],
        out: &mut [U],
    ) {
        if piece.is_empty() {
            return;
        }
        let slab_len = self.op.slab_len();
        let first = &self.op.tables[0];
        let g_rest = &self.g_rest;
        let g0 = &first.grid_offset;
        let n0 = first.n_cores;
        assert!(
            slab_len > 0 && piece.len().is_multiple_of(slab_len),
            "a piece of whole slabs"
        );
        let c0s = first_slab..first_slab + piece.len() / slab_len;
        assert!(c0s.end <= n0, "slabs within the grid's");
        let at = |c0: usize, j: usize| piece[(c0 - first_slab) * slab_len + j];
        // Grid row `j` is `out[j n0..(j + 1) n0]` (the robots'): bands of rows fill on every
        // thread.
        if g_rest.is_empty() {
            super::par::for_each_chunk_mut(
                out,
                TILE * n0,
                || (),
                |_, t, band| {
                    let js = t * TILE..t * TILE + band.len() / n0;
                    for c0s in tiles(c0s.clone(), NARROW) {
                        for (j, row) in js.clone().zip(band.chunks_mut(n0)) {
                            for c0 in c0s.clone() {
                                row[g0[c0]] = at(c0, j);
                            }
                        }
                    }
                },
            );
            return;
        }
        // Elsewhere runs of a slab's cores on every thread, where the values are words.
        #[cfg(feature = "parallel")]
        if scatter(
            out,
            piece,
            &Runs {
                first_slab,
                slab_len,
                g0,
                g_rest,
            },
        ) {
            return;
        }
        for band in tiles(c0s, NARROW) {
            for js in tiles(0..slab_len, TILE) {
                for c0 in band.clone() {
                    for j in js.clone() {
                        out[g0[c0] + g_rest[j]] = at(c0, j);
                    }
                }
            }
        }
    }
}

/// Slab cores per task of a scattered placing ([`scatter`]).
#[cfg(feature = "parallel")]
const SCATTER_RUN: usize = 4096;

/// Where a piece of whole slabs goes ([`SlabPlacer::place`]): slab core `j` of slab `c0`,
/// `piece[(c0 - first_slab) slab_len + j]`, to grid index `g0[c0] + g_rest[j]`.
#[cfg(feature = "parallel")]
struct Runs<'a> {
    first_slab: usize,
    slab_len: usize,
    g0: &'a [usize],
    g_rest: &'a [usize],
}

/// Places `piece` in `out` as `runs` says, every thread a run of a slab's cores for each of
/// the piece's slabs, each value stored atomically (the runs' grid indices interleave), and
/// returns `true`; `false` (nothing done) for values of other than 4 or 8 bytes.
#[cfg(feature = "parallel")]
fn scatter<U: bytemuck::Pod + Send + Sync>(out: &mut [U], piece: &[U], runs: &Runs<'_>) -> bool {
    use core::sync::atomic::{AtomicU32, AtomicU64};
    match size_of::<U>() {
        4 => {
            let out: &mut [u32] = bytemuck::cast_slice_mut(out);
            place_runs::<AtomicU32>(
                bytemuck::cast_slice(piece),
                zerocopy::transmute_mut!(out),
                runs,
            );
            true
        }
        8 => {
            let out: &mut [u64] = bytemuck::cast_slice_mut(out);
            place_runs::<AtomicU64>(
                bytemuck::cast_slice(piece),
                zerocopy::transmute_mut!(out),
                runs,
            );
            true
        }
        _ => false,
    }
}

/// The atomic twin of a 4- or 8-byte word ([`scatter`]).
#[cfg(feature = "parallel")]
trait AtomicWord: Sync {
    type Word: Copy + Sync;
    fn put(&self, x: Self::Word);
}

/// [`AtomicWord`] for each atomic and its word.
macro_rules! atomic_words {
    ($($atomic:ident => $word:ty),*) => {$(
        #[cfg(feature = "parallel")]
        impl AtomicWord for core::sync::atomic::$atomic {
            type Word = $word;
            #[inline(always)]
            fn put(&self, x: $word) {
                self.store(x, core::sync::atomic::Ordering::Relaxed);
            }
        }
    )*};
}
atomic_words!(AtomicU32 => u32, AtomicU64 => u64);

/// [`scatter`]'s loops, generic over the word so that each store is inlined: with an
/// indirect call per value the unit tests' three masses (11.4M cores) took 0.044-0.052 s to
/// place whole on two threads, 0.020-0.033 s so.
#[cfg(feature = "parallel")]
fn place_runs<A: AtomicWord>(piece: &[A::Word], out: &[A], r: &Runs<'_>) {
    let slabs = piece.len() / r.slab_len;
    let c0s = r.first_slab..r.first_slab + slabs;
    super::par::map_reduce(
        r.slab_len,
        SCATTER_RUN,
        (),
        |run| {
            for band in tiles(c0s.clone(), NARROW) {
                for js in tiles(run.clone(), TILE) {
                    for c0 in band.clone() {
                        let (g, from) = (r.g0[c0], (c0 - r.first_slab) * r.slab_len);
                        for j in js.clone() {
                            out[g + r.g_rest[j]].put(piece[from + j]);
                        }
                    }
                }
            }
        },
        |(), ()| (),
    );
}
