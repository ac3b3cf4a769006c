//! The shape of a run's block path on the GPU: the blocks' sizes from the core's
//! [`BlockPlan`](fuzzyq_core::solver::BlockPlan), the batches a pass runs in, the parts of
//! the per-core buffers and of any stage output over one storage binding, and the base
//! parameters of every dispatch.

use crate::batches::{Batches, Tree};
use crate::error::GpuError;
use crate::gpu::Evaluation;
use crate::kernels::{MAX_BLOCKS, Params};
use crate::parts::Parts;

/// The shape of the block path, from [`fuzzyq_core::solver::BlockPlan`].
#[derive(Clone, Debug)]
pub(crate) struct Shape {
    /// Cores.
    pub(crate) n: usize,
    /// Per block (contraction order): (cores, actions, R, P).
    pub(crate) blocks: Vec<[u32; 4]>,
    /// Per block: the index of its first row start in the joint `row_ptr` buffer.
    pub(crate) row_base: Vec<u32>,
    /// Per block: its rows' entries, every core and action.
    pub(crate) entries: Vec<u64>,
    /// Joint actions.
    pub(crate) n_joint: u32,
    /// Product actions (`P` of the last block times its actions).
    pub(crate) n_product: u64,
    /// The blocks' sizes for batching, and the batches a pass runs in.
    pub(crate) tree: Tree,
    pub(crate) batches: Batches,
    /// The parts of the per-core buffers.
    pub(crate) parts: Parts,
    /// Per written stage: its output's parts where one batch's exceeds a storage binding
    /// ([`Shape::stage_cut`]), else `None`.
    pub(crate) stage_parts: Vec<Option<Parts>>,
    /// Whether the last stage reduces in place (the identity action map and a state-only
    /// reward); else it writes full rows that `reduce_rows` reduces.
    pub(crate) fused: bool,
    /// Whether the absolute maximum reduces in place (the identity map).
    pub(crate) fused_abs: bool,

    pub(crate) gamma: f32,
    pub(crate) has_goal: bool,
    pub(crate) reward_table: bool,
    pub(crate) can_evaluate: bool,
}

impl Shape {
    /// The shape of `plan`'s block path over `n` cores, its blocks' sizes and row bases from
    /// `BlockArrays` (`sweeps.rs`); batches of one slab until [`Self::batch_within`].
    pub(crate) fn of(
        plan: &fuzzyq_core::solver::BlockPlan<'_, f32>,
        n: usize,
        blocks: Vec<[u32; 4]>,
        row_base: Vec<u32>,
        parts: Parts,
    ) -> Self {
        let last = plan.tables.last().expect("at least one block");
        let identity = plan.joint_to_product.is_none();
        let reward_table = plan.rewards.is_none();
        let n_product = (last.p_len * last.n_actions) as u64;
        let (fused, fused_abs) = (identity && !reward_table, identity);
        let rows = (!fused || !fused_abs).then_some(n_product);
        let tree = Tree::new(&blocks, rows);
        Self {
            n,
            batches: tree.batches(0, 1),
            tree,
            parts,
            stage_parts: Vec::new(),
            blocks,
            row_base,
            entries: plan.tables.iter().map(|t| t.col.len() as u64).collect(),
            n_joint: plan.n_joint as u32,
            n_product,
            fused,
            fused_abs,
            gamma: plan.gamma,
            has_goal: !plan.goal.is_empty(),
            reward_table,
            can_evaluate: plan.can_evaluate,
        }
    }

    /// Whether some pass writes full rows for `reduce_rows` (a renumbered joint action or a
    /// reward of the action).
    pub(crate) fn writes_rows(&self) -> bool {
        self.rows_bytes().is_some()
    }

    /// Batches whose largest buffer takes at most `budget` bytes where one item's can
    /// ([`Tree::choose`]), runs of slabs never straddling two parts; a stage output over one
    /// storage binding of `max_binding` bytes cut into parts ([`Self::stage_cut`]), a
    /// kernel binding at most `max_parts` parts in group 1.
    pub(crate) fn batch_within(
        &mut self,
        budget: u64,
        max_binding: u64,
        max_parts: u64,
    ) -> Result<(), GpuError> {
        self.batches = self.tree.choose(budget.min(max_binding));
        if self.batches.level == 0 && self.parts.count() > 1 {
            // Parts start at multiples of `per` slabs: batches of a divisor of it.
            let per = self.parts.per;
            let items = (1..=self.batches.items.min(per))
                .rev()
                .find(|&i| per.is_multiple_of(i))
                .expect("1 divides");
            self.batches = self.tree.batches(0, items);
        }
        self.stage_parts = (0..self.written_stages())
            .map(|b| self.stage_cut(b, max_binding))
            .collect::<Result<_, _>>()?;
        // Group 1 of stage `b`: the parts it reads and those it writes.
        let count = |p: Option<&Parts>| p.map_or(0, Parts::count);
        let bound = (0..self.written_stages())
            .map(|b| {
                let reads = match b {
                    0 => self.parts.count(),
                    b => count(self.stage_parts[b - 1].as_ref()),
                };
                reads + count(self.stage_parts[b].as_ref())
            })
            .max()
            .unwrap_or(0);
        if bound as u64 > max_parts {
            return Err(GpuError::TooManyParts {
                parts: bound,
                limit: max_parts,
            });
        }
        Ok(())
    }

    /// Stage `b`'s output for one batch cut into parts of at most `max_binding` bytes where it
    /// exceeds one storage binding (`None` where it does not; only a held ancestor's can, as
    /// three point masses on the paper's cores have one slab's first stage, 3.69 GB): whole
    /// units of the values one column of the next stage's rows reads (its `R P`), so that the
    /// next stage finds a column's values in one part. Refused where the last stage would read
    /// parts (its input is the batch's own, which the budget bounds), where a unit exceeds a
    /// binding, or where an index of the output would not fit `u32`.
    pub(crate) fn stage_cut(&self, b: usize, max_binding: u64) -> Result<Option<Parts>, GpuError> {
        let bytes = self.stage_bytes(b);
        if bytes <= max_binding {
            return Ok(None);
        }
        if b + 2 == self.n_blocks() {
            return Err(GpuError::over_binding(
                "the last stage's input for one batch",
                bytes,
                max_binding,
            ));
        }
        if bytes / 4 > u64::from(u32::MAX) {
            return Err(GpuError::Unsupported(
                "runs stage outputs of at most 2^32 values for one batch",
            ));
        }
        let [_, _, r, p] = self.blocks[b + 1];
        let unit = u64::from(r) * u64::from(p);
        if 4 * unit > max_binding {
            return Err(GpuError::over_binding(
                "one column's values of a stage's output",
                4 * unit,
                max_binding,
            ));
        }
        Parts::new(bytes / 4 / unit, unit, max_binding, max_binding, u64::MAX).map(Some)
    }

    /// The stages a policy-evaluation sweep runs for every action before a thread per core
    /// nests its own action's rows of the other blocks ([`Evaluation`]): among those whose
    /// last output is one buffer (none reads `V`), the least work ([`evaluation_work`], with
    /// the stages whose kernels have their rows compiled in: `compiled_in`), or the most up
    /// to the number asked for.
    pub(crate) fn evaluation_stages(&self, evaluation: Evaluation, compiled_in: &[bool]) -> usize {
        let whole = |k: usize| k == 0 || self.stage_parts.get(k - 1).is_some_and(Option::is_none);
        let mut splits = (0..self.n_blocks()).filter(|&k| whole(k));
        let least = |splits| {
            least_work(
                &self.blocks,
                &self.entries,
                self.n as f64,
                compiled_in,
                splits,
            )
        };
        match evaluation {
            Evaluation::Stages(k) => splits.rfind(|&s| s <= k as usize),
            Evaluation::Auto => least(splits),
        }
        .unwrap_or(0)
    }

    /// Bytes of the buffer of stage `b`'s output for one batch.
    pub(crate) fn stage_bytes(&self, b: usize) -> u64 {
        self.tree.stage_bytes(b, &self.batches)
    }

    /// Bytes of the full rows of one batch, where a pass writes them.
    pub(crate) fn rows_bytes(&self) -> Option<u64> {
        self.tree.rows_bytes(&self.batches)
    }

    pub(crate) fn n_blocks(&self) -> usize {
        self.blocks.len()
    }

    /// The stages whose outputs go to memory (those before the last).
    pub(crate) fn written_stages(&self) -> usize {
        self.n_blocks() - 1
    }

    /// The base parameters of every dispatch.
    pub(crate) fn params(&self) -> Params {
        let mut blocks = [[0u32; 4]; MAX_BLOCKS];
        let mut rows = [[0u32; 4]; MAX_BLOCKS];
        for (b, blk) in self.blocks.iter().enumerate() {
            blocks[b] = *blk;
            rows[b][0] = self.row_base[b];
        }
        Params {
            n_joint: self.n_joint,
            has_map: 0,
            reward_table: u32::from(self.reward_table),
            has_goal: u32::from(self.has_goal),
            gamma: self.gamma,
            n_blocks: self.blocks.len() as u32,
            blocks,
            rows,
            ..Params::default()
        }
    }
}

/// Multiply-adds of a policy-evaluation sweep over `n` cores of `blocks` (`[cores, actions,
/// R, P]` in contraction order, with `entries` row entries each) that runs the first `stages`
/// stages of a full backup for every action (each block's row entries times the elements each
/// feeds), then per core the sums over its action's rows of the other blocks, nested (the
/// products of their mean row lengths from the innermost block out, summed): `(each stage's,
/// nested)`.
pub(crate) fn evaluation_multiply_adds(
    blocks: &[[u32; 4]],
    entries: &[u64],
    n: f64,
    stages: usize,
) -> (Vec<f64>, f64) {
    let mut staged = Vec::new();
    // Items of the stage before `b`.
    let mut items = 1.0;
    for (&[cores, _, r, p], &e) in blocks.iter().zip(entries).take(stages) {
        staged.push(items * f64::from(r) * f64::from(p) * e as f64);
        items *= f64::from(cores);
    }
    let (mut nested, mut product) = (0.0, 1.0);
    for (&[cores, a, _, _], &e) in blocks.iter().zip(entries).skip(stages).rev() {
        product *= e as f64 / (f64::from(cores) * f64::from(a));
        nested += n * product;
    }
    (staged, nested)
}

/// What a multiply-add of a stage whose block rows are compiled into its kernel costs, in
/// nested ones: a nested multiply-add loads its row entry's weight and column and gathers its
/// value, as a stage's does where it reads its rows from the tables, but the compiled-in ones
/// hold the weights and columns as constants. On lavapipe a nested multiply-add takes about 12
/// times as long as a full backup's (rows compiled in); 1/4 to 1/2 pick the fastest split of
/// each problem measured there (the paper's grid, reduced grids of two and three point masses),
/// so 1/3. Khepera's blocks, too large to compile in, run nested (2.2 entries per row: 2.6e8
/// multiply-adds nested, 4.1e8 from one stage, which took 11% longer).
const COMPILED_IN_COST: f64 = 1.0 / 3.0;

/// The work of a split whose multiply-adds are `(each stage's, nested)`
/// ([`evaluation_multiply_adds`]), in nested multiply-adds: those of the stages with their rows
/// compiled in (`compiled_in[b]`) count [`COMPILED_IN_COST`] each.
pub(crate) fn evaluation_work((staged, nested): (Vec<f64>, f64), compiled_in: &[bool]) -> f64 {
    let stage = |(b, f): (usize, &f64)| {
        if compiled_in.get(b).copied().unwrap_or(false) {
            f * COMPILED_IN_COST
        } else {
            *f
        }
    };
    staged.iter().enumerate().map(stage).sum::<f64>() + nested
}

/// Among `splits`, the one with the least [`evaluation_work`] over `n` cores of `blocks`
/// (`entries` row entries each; `compiled_in`: the stages whose rows are compiled in), the
/// first of equals.
pub(crate) fn least_work(
    blocks: &[[u32; 4]],
    entries: &[u64],
    n: f64,
    compiled_in: &[bool],
    splits: impl Iterator<Item = usize>,
) -> Option<usize> {
    let work = |k| evaluation_work(evaluation_multiply_adds(blocks, entries, n, k), compiled_in);
    splits.min_by(|&a, &b| work(a).total_cmp(&work(b)))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `agents` point masses (two blocks each) of `n` cores and `a` actions per block, rows of
    /// `per_row` entries: blocks, entries and cores.
    fn masses(agents: u32, n: u32, a: u32, per_row: f64) -> (Vec<[u32; 4]>, Vec<u64>, f64) {
        let nb = 2 * agents;
        let blocks: Vec<[u32; 4]> = (0..nb)
            .map(|b| [n, a, n.pow(nb - 1 - b), a.pow(b)])
            .collect();
        let entries = vec![(f64::from(n * a) * per_row) as u64; nb as usize];
        (blocks, entries, f64::from(n).powi(nb as i32))
    }

    /// The split with the least work, every stage compiled in or none, and how many times
    /// fewer multiply-adds it takes than nested per core.
    fn least(m: &(Vec<[u32; 4]>, Vec<u64>, f64), compiled: bool) -> (usize, f64) {
        let sum = |k| {
            let (s, n) = evaluation_multiply_adds(&m.0, &m.1, m.2, k);
            s.iter().sum::<f64>() + n
        };
        let compiled_in = vec![compiled; m.0.len()];
        let best = least_work(&m.0, &m.1, m.2, &compiled_in, 0..m.0.len()).unwrap();
        (best, sum(0) / sum(best))
    }

    #[test]
    fn evaluation_runs_the_stages_that_save_work() {
        // Nested per core over V: every block's mean row length multiplied out, summed.
        let one = masses(1, 4, 2, 2.0);
        let fmas = |k| evaluation_multiply_adds(&one.0, &one.1, one.2, k);
        assert_eq!(fmas(0), (vec![], 16.0 * (4.0 + 2.0)));
        // One stage: block 0's 16 entries feed the 4 cores of block 1, then 2 per core.
        assert_eq!(fmas(1), (vec![64.0], 16.0 * 2.0));
        assert_eq!(evaluation_work(fmas(1), &[false, false]), 64.0 + 32.0);
        assert_eq!(evaluation_work(fmas(1), &[true, true]), 64.0 / 3.0 + 32.0);
        // On the paper's cores (rows of 3.66 entries on average), as measured on lavapipe for
        // the paper's grid: two stages, 2.0 times fewer multiply-adds than nested; one where
        // the stages read their rows from the tables.
        let paper = masses(2, 45, 5, 3.66);
        let (k, gain) = least(&paper, true);
        assert_eq!(k, 2);
        assert!((1.9..2.1).contains(&gain), "{gain}");
        assert_eq!(least(&paper, false).0, 1);
        // Three masses: three stages, with 3 forces per axis 16 times fewer multiply-adds,
        // with 5 (more actions per element of the later stages) 5 times fewer.
        for (a, gains) in [(3, 15.0..17.0), (5, 5.0..5.5)] {
            let (k, gain) = least(&masses(3, 45, a, 3.66), true);
            assert_eq!(k, 3, "{a}");
            assert!(gains.contains(&gain), "{a}: {gain}");
        }
        // Khepera's blocks (6,137 cores, 4 actions, 2.19 entries per row), too large to
        // compile in: nested.
        let khepera = (
            vec![[6137, 4, 6137, 1], [6137, 4, 1, 4]],
            vec![53718, 53718],
            6137.0 * 6137.0,
        );
        assert_eq!(least(&khepera, false).0, 0);
    }
}
