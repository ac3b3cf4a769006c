//! How a full backup is cut into batches that bound the stage buffers.
//!
//! The block contraction (`fuzzyq_core::solver::BlockPlan`) runs stage `b` for every prefix
//! `(c_0, ..., c_b)` of the contraction order's block cores: an *item* of level `b`. Its
//! output (`R_b A_b P_b` values: the later blocks' input cores, block `b`'s actions and the
//! earlier blocks' actions) is read by the items of level `b + 1` below it, and the last
//! stage's items are the cores.
//!
//! A batch is a run of consecutive items of one level `L` below one item of level `L - 1`.
//! The stages before `L` hold the batch's single ancestor at their level, computed when a
//! batch first needs it and kept for the batches after it (the batches run in order, so each
//! ancestor is computed once per pass); the stages from `L` on hold every descendant of the
//! batch. Level 0 is a run of slabs. [`Tree::choose`] takes the lowest level at which one item
//! per batch fits the byte budget (the fewest dispatches), then as many items as fit: three
//! point masses on the paper's cores take level 2, where a slab's later stages would take
//! terabytes. Every element is the same sum whatever the batches, so any choice gives
//! the same bits.

use core::fmt;

/// How the passes of a [`GpuSweeps`](crate::GpuSweeps) run are batched
/// ([`GpuSweeps::batches`](crate::GpuSweeps::batches)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Batches {
    /// The level of a batch's items: each batch fixes the cores of the first `level`
    /// contracted blocks and runs `items` consecutive cores of the next (0: `items` slabs).
    pub level: usize,
    /// Items per batch (the last batch below an ancestor may hold fewer).
    pub items: u64,
    /// Batches per full pass.
    pub count: u64,
}

impl fmt::Display for Batches {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let s = |n: u64| if n == 1 { "" } else { "es" };
        if self.level == 0 {
            let slabs = if self.items == 1 { "slab" } else { "slabs" };
            write!(
                f,
                "{} batch{} of {} {slabs}",
                self.count,
                s(self.count),
                self.items
            )
        } else {
            let fixed = match self.level {
                1 => "block 0".to_string(),
                l => format!("blocks 0-{}", l - 1),
            };
            write!(
                f,
                "{} batch{} of {} core(s) of block {} below fixed cores of {fixed}",
                self.count,
                s(self.count),
                self.items,
                self.level,
            )
        }
    }
}

/// One dispatch of a pass's stage: `items` items of level `stage` from item `lo` on, reading
/// the stage before it from its item `src_lo` on (0 for the first stage, which reads `V`).
/// For the last stage the items are cores.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Step {
    pub stage: usize,
    pub lo: u64,
    pub items: u64,
    pub src_lo: u64,
}

/// The sizes batching needs, per block in contraction order.
#[derive(Clone, Debug)]
pub(crate) struct Tree {
    /// Block cores.
    n: Vec<u64>,
    /// Elements of one item's stage output (`R_b A_b P_b`; the last block's is not written).
    item_len: Vec<u64>,
    /// Elements per core of the full rows, where a pass writes them (else 0).
    row_len: u64,
}

impl Tree {
    /// The tree of blocks `[cores, actions, R, P]` (contraction order); `row_len`: elements
    /// of a core's full rows where some pass writes them.
    pub(crate) fn new(blocks: &[[u32; 4]], row_len: Option<u64>) -> Self {
        Self {
            n: blocks.iter().map(|b| u64::from(b[0])).collect(),
            item_len: blocks
                .iter()
                .map(|&[_, a, r, p]| u64::from(r) * u64::from(a) * u64::from(p))
                .collect(),
            row_len: row_len.unwrap_or(0),
        }
    }

    /// Elements of one item's output at stage `b`.
    pub(crate) fn item_len(&self, b: usize) -> u64 {
        self.item_len[b]
    }

    fn last(&self) -> usize {
        self.n.len() - 1
    }

    /// Items of level `to` below one item of level `from` (`from <= to`; `from` may be -1,
    /// the root, written as `None`).
    fn below(&self, from: Option<usize>, to: usize) -> u64 {
        let first = from.map_or(0, |f| f + 1);
        self.n[first..=to].iter().product()
    }

    /// Items of stage `b`'s buffer in a batch of `items` items of `level`.
    fn stage_items(&self, b: usize, level: usize, items: u64) -> u64 {
        if b < level {
            1
        } else {
            items * self.below(Some(level), b)
        }
    }

    /// Bytes of stage `b`'s buffer (`b` before the last).
    pub(crate) fn stage_bytes(&self, b: usize, batches: &Batches) -> u64 {
        4 * self.stage_items(b, batches.level, batches.items) * self.item_len[b]
    }

    /// Bytes of the full rows of a batch, where a pass writes them.
    pub(crate) fn rows_bytes(&self, batches: &Batches) -> Option<u64> {
        (self.row_len > 0)
            .then(|| 4 * self.stage_items(self.last(), batches.level, batches.items) * self.row_len)
    }

    /// The largest buffer of a batch of `items` items of `level`, in bytes (at least 4).
    fn largest(&self, level: usize, items: u64) -> u64 {
        self.largest_from(0, level, items)
    }

    /// The largest buffer of stages `first..` (and the rows) of a batch of `items` items of
    /// `level`, in bytes (at least 4).
    fn largest_from(&self, first: usize, level: usize, items: u64) -> u64 {
        let b = Batches {
            level,
            items,
            count: 0,
        };
        (first..self.last())
            .map(|s| self.stage_bytes(s, &b))
            .chain(self.rows_bytes(&b))
            .max()
            .unwrap_or(0)
            .max(4)
    }

    /// The batches whose largest buffer fits `budget` bytes: the lowest level at which one
    /// item does, with as many items as fit. Where no level's one item fits, the level whose
    /// one item's largest buffer is smallest (one slab's first stage, at its level: the
    /// caller cuts a buffer over a storage binding into parts), with as many items as keep
    /// the batch's own buffers (the stages from its level on, which grow with its items)
    /// within the budget, or one.
    pub(crate) fn choose(&self, budget: u64) -> Batches {
        let levels = 0..=self.last();
        let floor = levels
            .clone()
            .map(|l| self.largest(l, 1))
            .min()
            .expect("at least one block");
        let level = levels
            .into_iter()
            .find(|&l| self.largest(l, 1) <= budget.max(floor))
            .expect("the floor fits");
        let own = |m: u64| self.largest_from(level, level, m);
        let budget = budget.max(own(1));
        let fits = |m: u64| own(m) <= budget;
        // The largest buffer grows linearly in the items: bisect the largest that fits.
        let (mut lo, mut hi) = (1u64, self.n[level]);
        while lo < hi {
            let mid = lo + (hi - lo).div_ceil(2);
            if fits(mid) {
                lo = mid;
            } else {
                hi = mid - 1;
            }
        }
        self.batches(level, lo)
    }

    /// Batches of `items` items of `level` (at most the cores of block `level`).
    pub(crate) fn batches(&self, level: usize, items: u64) -> Batches {
        Batches {
            level,
            items,
            count: self.parents(level) * self.n[level].div_ceil(items),
        }
    }

    /// Items of level `level - 1` (one, the root, for level 0).
    fn parents(&self, level: usize) -> u64 {
        level.checked_sub(1).map_or(1, |p| self.below(None, p))
    }

    /// The largest buffer of `batches`, in bytes.
    #[cfg(test)]
    pub(crate) fn largest_of(&self, batches: &Batches) -> u64 {
        self.largest(batches.level, batches.items)
    }

    /// Every stage dispatch of one full pass in `batches`, in order: per batch the ancestors
    /// it needs that the stage buffers do not hold yet, then its own stages down to the last.
    pub(crate) fn steps(&self, batches: &Batches) -> Vec<Step> {
        let mut steps = Vec::new();
        let Batches { level, items, .. } = *batches;
        let last = self.last();
        let parents = self.parents(level);
        let width = self.n[level];
        let mut held: Vec<Option<u64>> = vec![None; level];
        for parent in 0..parents {
            let mut first = 0;
            while first < width {
                let count = items.min(width - first);
                let g = parent * width + first;
                let mut src_lo = 0;
                for (b, h) in held.iter_mut().enumerate() {
                    let ancestor = g / self.below(Some(b), level);
                    if *h != Some(ancestor) {
                        *h = Some(ancestor);
                        steps.push(Step {
                            stage: b,
                            lo: ancestor,
                            items: 1,
                            src_lo,
                        });
                    }
                    src_lo = ancestor;
                }
                for stage in level..=last {
                    let per = self.below(Some(level), stage);
                    let lo = g * per;
                    steps.push(Step {
                        stage,
                        lo,
                        items: count * per,
                        src_lo,
                    });
                    src_lo = lo;
                }
                first += count;
            }
        }
        steps
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Three blocks of 3, 4 and 5 cores with 2, 3 and 2 actions (contraction order).
    fn tree(rows: bool) -> Tree {
        // R_b: cores of the later blocks; P_b: actions of the earlier ones.
        let blocks = [[3, 2, 20, 1], [4, 3, 5, 2], [5, 2, 1, 6]];
        Tree::new(&blocks, rows.then_some(12))
    }

    /// Which items of each level a pass computes, and from which source items: every core
    /// once, every item's parent held when it runs.
    fn check(t: &Tree, b: &Batches) {
        let last = t.last();
        let mut done: Vec<Vec<u32>> = (0..=last)
            .map(|s| vec![0; t.below(None, s) as usize])
            .collect();
        // The items each stage buffer holds: [lo, lo + items).
        let mut held: Vec<(u64, u64)> = vec![(0, 0); last + 1];
        let mut batches = 0;
        for s in t.steps(b) {
            if s.stage == last {
                batches += 1;
            }
            for g in s.lo..s.lo + s.items {
                done[s.stage][g as usize] += 1;
                if s.stage > 0 {
                    let parent = g / t.n[s.stage];
                    let (lo, n) = held[s.stage - 1];
                    assert!((lo..lo + n).contains(&parent), "{s:?} reads {parent}");
                    assert_eq!(s.src_lo, lo);
                }
            }
            assert!(
                4 * s.items * t.item_len[s.stage] <= t.largest_of(b) || s.stage == last,
                "{s:?}"
            );
            held[s.stage] = (s.lo, s.items);
        }
        assert_eq!(batches, b.count);
        for (s, d) in done.iter().enumerate() {
            assert!(d.iter().all(|&x| x == 1), "stage {s}: {d:?}");
        }
    }

    #[test]
    fn every_level_and_width_computes_every_item_once_from_held_parents() {
        for rows in [false, true] {
            let t = tree(rows);
            for level in 0..=t.last() {
                for items in 1..=t.n[level] {
                    check(&t, &t.batches(level, items));
                }
            }
        }
    }

    #[test]
    fn the_chosen_batches_fit_the_budget_where_one_item_does() {
        for rows in [false, true] {
            let t = tree(rows);
            let mut levels = Vec::new();
            for budget in [1, 16, 64, 100, 200, 400, 1000, 5000, 1 << 20] {
                let b = t.choose(budget);
                levels.push(b.level);
                if t.largest(b.level, 1) <= budget {
                    assert!(t.largest_of(&b) <= budget, "{b:?} over {budget}");
                    assert!(b.items == t.n[b.level] || t.largest(b.level, b.items + 1) > budget);
                    assert!((0..b.level).all(|l| t.largest(l, 1) > budget));
                }
            }
            assert!(levels.contains(&0) && levels.contains(&1), "{levels:?}");
            assert!(levels.windows(2).all(|w| w[0] >= w[1]), "{levels:?}");
        }
    }

    #[test]
    fn a_budget_for_all_slabs_is_one_batch() {
        let t = tree(false);
        let b = t.choose(1 << 30);
        assert_eq!((b.level, b.items, b.count), (0, 3, 1));
        assert_eq!(b.to_string(), "1 batch of 3 slabs");
        // Where no level fits, the lowest level whose largest buffer is smallest, with as many
        // items as that buffer's size allows: with full rows the deepest (a few cores' rows),
        // else from level 1 on the first stage's one slab dominates.
        assert_eq!(t.choose(1), t.batches(1, 1));
        let deep = tree(true).choose(1);
        assert_eq!((deep.level, deep.items, deep.count), (2, 1, 60));
        assert_eq!(
            deep.to_string(),
            "60 batches of 1 core(s) of block 2 below fixed cores of blocks 0-1"
        );
        // Its own buffers (the stages from its level on) within a budget that one item's
        // ancestors exceed: as many items as fit it.
        let fixed = tree(true).largest_from(0, 2, 1);
        let own = tree(true).largest_from(2, 2, 1);
        assert!(fixed > 2 * own, "{fixed} {own}");
        assert_eq!(tree(true).choose(2 * own).items, 2);
    }

    /// Three point masses: six blocks of `n` cores and `a` actions (contraction order).
    fn three_masses(n: u32, a: u32) -> Tree {
        let blocks: Vec<[u32; 4]> = (0..6).map(|b| [n, a, n.pow(5 - b), a.pow(b)]).collect();
        Tree::new(&blocks, None)
    }

    #[test]
    fn the_papers_three_masses_index_within_u32_and_batch_within_parts() {
        // 45^6 = 8.3e9 cores: every index a dispatch passes the shaders (an item counted from
        // its source's first child, a count of elements) fits u32, and the last stage's
        // batches (cores) lie within one part of V.
        let t = three_masses(45, 5);
        let b = t.choose(256 << 20);
        let max = u64::from(u32::MAX);
        // wgpu's largest binding: 23 parts of 2 slabs.
        let binding = (1 << 31) - 4;
        let parts = crate::parts::Parts::new(45, 45u64.pow(5), binding, binding, 100).unwrap();
        let mut last = 0;
        for s in t.steps(&b) {
            assert!(s.lo - s.src_lo * t.n[s.stage] <= max, "{s:?}");
            assert!(s.items * t.item_len[s.stage] <= max, "{s:?}");
            if s.stage == t.last() {
                assert_eq!(parts.of_core(s.lo), parts.of_core(s.lo + s.items - 1));
                assert_eq!(s.lo, last, "the cores in order");
                last = s.lo + s.items;
            }
        }
        assert_eq!(last, 45u64.pow(6));
        assert!(last > max);
    }

    #[test]
    fn three_point_masses_on_the_papers_cores_batch_below_two_blocks() {
        // Six blocks of 45 cores and 5 actions: one slab's first stage (45^5 x 5 values,
        // 3.69 GB, over a binding: cut into parts) is the smallest largest buffer; below two
        // fixed blocks, one core of the third, whose last written stage (1.14 GB) is over
        // the budget but within a binding.
        let t = three_masses(45, 5);
        let b = t.choose(256 << 20);
        assert_eq!((b.level, b.items, b.count), (2, 1, 45 * 45 * 45));
        assert_eq!(t.largest_of(&b), 4 * 45u64.pow(5) * 5);
        assert_eq!(t.largest_from(2, 2, 1), 4 * 45u64.pow(3) * 5u64.pow(5));
        // With 3 forces per axis, three cores of the third fit the budget.
        let t = three_masses(45, 3);
        let b = t.choose(256 << 20);
        assert_eq!((b.level, b.items, b.count), (2, 3, 45 * 45 * 15));
        assert!(t.largest_from(2, 2, 3) <= 256 << 20);
        // examples/three-point-masses.toml: 21 cores and 3 actions per block; one slab's last
        // written stage would take 3.97 GB, one core of block 1's 189 MB.
        let t = three_masses(21, 3);
        assert_eq!(t.largest(0, 1), 4 * 21u64.pow(4) * 21 * 243);
        let b = t.choose(256 << 20);
        assert_eq!((b.level, b.items, b.count), (1, 1, 441));
        assert_eq!(t.largest_of(&b), 4 * 21u64.pow(3) * 21 * 243);
    }
}
