//! The shape of a run's block path on the GPU: the blocks' sizes from the core's
//! [`BlockPlan`](fuzzyq_core::solver::BlockPlan), the batches a pass runs in, the parts of
//! the per-core buffers and of any stage output over one storage binding, and the base
//! parameters of every dispatch.

use crate::batches::{Batches, Tree};
use crate::error::GpuError;
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
