//! Decisions on the block path (`block.rs`): `Q(x, .)` at any state from the blocks' tables,
//! mixing the active block cores' rows first and contracting them with the box of `V` they
//! reach.

use super::*;

impl<T: Real> BlockOperator<T> {
    /// `Q(x, .)` at any state from `v` in grid order (see [`Operator::q_values`]).
    ///
    /// The active cores of `x` are the products of each block's active block cores, and their
    /// memberships the products of the block memberships, so
    /// `sum_d mu_d(x) P[d, u] V = sum_k prod_b (sum_{c_b} mu_{c_b} T_b[c_b, a_b, k_b]) V[k]`:
    /// the same contraction with one mixed row per block and action, over the box of
    /// successor cores those rows reach.
    ///
    /// Layout and arithmetic: the box of `V` is gathered with the blocks in gather order (the
    /// block of the largest grid strides slowest), so its innermost rows are nearby values of
    /// `V`; the stages contract it in that order, one block at a time (`[p][k][r]` to
    /// `[p][a][r]`), on the operator's run-time kernel: each element sums its row's entries in
    /// increasing successor core with fused multiply-adds from 0, as the backup's kernels do,
    /// so every kernel instance gives the same bits. Each mixed weight is summed over the
    /// active block cores in their order. The buffers are kept between calls.
    pub(in crate::solver) fn q_values<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &[T],
        x: &[T],
        out: &mut [T],
    ) -> Result<(), SolveError> {
        // Validates the state (length, finite values).
        op.grid.active(x)?;
        let pool = || self.q.work.lock().unwrap_or_else(PoisonError::into_inner);
        let taken = pool().pop();
        let mut w = taken.unwrap_or_else(|| self.q_work_new(op));
        self.q_values_in(op, v, x, out, &mut w);
        pool().push(w);
        Ok(())
    }

    /// Fresh buffers for [`Self::q_values`].
    fn q_work_new<M: Model<T> + Sync + ?Sized>(&self, op: &Operator<'_, T, M>) -> QWork<T> {
        let nb = self.tables.len();
        let most = self.tables.iter().map(|t| t.n_cores).max().unwrap_or(0);
        let mj = op.joint.n_joint();
        QWork {
            mixed: (0..nb).map(|_| LocalRows::default()).collect(),
            pure: (0..nb).map(|_| LocalRows::default()).collect(),
            support: vec![Vec::new(); nb],
            local: self.tables.iter().map(|t| vec![0; t.n_cores]).collect(),
            grid_offset: vec![Vec::new(); nb],
            act: Vec::new(),
            hit: Vec::new(),
            dense: vec![T::ZERO; most],
            touched: vec![false; most],
            in_support: vec![false; most],
            vbox: Vec::new(),
            cores: Vec::new(),
            ev: Vec::new(),
            tmp: Vec::new(),
            ev_core: Vec::new(),
            reward: vec![T::ZERO; mj],
            goal_ev: vec![T::ZERO; mj],
            drop: vec![false; mj],
            corrections: Vec::new(),
            x: vec![T::ZERO; op.state_dim()],
            u: vec![T::ZERO; op.joint.dim()],
        }
    }

    /// [`Self::q_values`] on buffers `w`, for a validated state.
    fn q_values_in<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
        v: &[T],
        x: &[T],
        out: &mut [T],
        w: &mut QWork<T>,
    ) {
        let grid = &op.grid;
        let e = grid.n_dims();
        let nb = self.tables.len();
        let mut seg = [Segment {
            lower: 0,
            upper_weight: T::ZERO,
        }; MAX_DIMS];
        for (s, (p, &xe)) in seg.iter_mut().zip(grid.dims().iter().zip(x)) {
            *s = p.locate(xe);
        }

        self.mix_blocks(&seg, w);

        // The active cores (internal index, membership), in increasing row-major order.
        w.cores.clear();
        for_each_core(&seg[..e], |idx, mu| {
            let internal = idx
                .iter()
                .zip(&self.q.internal_strides)
                .map(|(i, s)| i * s)
                .sum::<usize>();
            w.cores.push((internal, mu));
        });

        let sizes = self.gather_box(v, w);
        self.contract_box(&w.mixed, &sizes[..nb], &w.vbox, &mut w.ev, &mut w.tmp);

        // Rewards of the active cores, and the expectations of goal cores and of transitions
        // into terminal states, to take back out (per joint action).
        let mj = op.joint.n_joint();
        let depends = op.model.reward_depends_on_action();
        let state_rewards = op.rewards.as_deref().filter(|_| !depends);
        let mut reward = T::ZERO;
        if depends {
            w.reward.fill(T::ZERO);
        } else if state_rewards.is_none() {
            op.joint.vector_unchecked(0, &mut w.u);
        }
        let check = op.backup.absorbing_goal || self.terminals.is_some();
        w.corrections.clear();
        for &(internal, mu) in &w.cores {
            match state_rewards {
                Some(r) => reward += mu * r[internal],
                None => {
                    op.core_state(internal, &mut w.x);
                    if depends {
                        for (u, r) in w.reward.iter_mut().enumerate() {
                            op.joint.vector_unchecked(u, &mut w.u);
                            *r += mu * op.model.reward(&w.x, &w.u);
                        }
                    } else {
                        reward += mu * op.model.reward(&w.x, &w.u);
                    }
                }
            }
            if check && (op.is_goal(internal) || !self.terminal_actions(internal).is_empty()) {
                w.corrections.push((internal, mu));
            }
        }
        let mut any_goal = false;
        if !w.corrections.is_empty() {
            w.goal_ev.fill(T::ZERO);
            for i in 0..w.corrections.len() {
                let (internal, mu) = w.corrections[i];
                // The joint actions whose expectation drops out: all of them at a goal core,
                // else those leading to a terminal state.
                let goal = op.is_goal(internal);
                w.drop.fill(goal);
                if !goal {
                    for &u in self.terminal_actions(internal) {
                        w.drop[u as usize] = true;
                    }
                }
                any_goal = true;
                // This core's pure rows, over the box.
                for (b, t) in self.tables.iter().enumerate() {
                    let c = (internal / self.r_len[b]) % t.n_cores;
                    let rows = &mut w.pure[b];
                    rows.clear();
                    for a in 0..t.n_actions {
                        let (cols, ws) = t.row(c, a);
                        for (&k, &wk) in cols.iter().zip(ws) {
                            rows.col.push(w.local[b][k as usize]);
                            rows.weight.push(wk);
                        }
                        rows.ptr.push(rows.col.len() as u32);
                    }
                }
                self.contract_box(&w.pure, &sizes[..nb], &w.vbox, &mut w.ev_core, &mut w.tmp);
                for (u, g) in w.goal_ev.iter_mut().enumerate() {
                    if w.drop[u] {
                        *g += mu * w.ev_core[self.q.q_index[u] as usize];
                    }
                }
            }
        }
        let gamma = op.gamma;
        for (u, o) in out[..mj].iter_mut().enumerate() {
            let f = self.q.q_index[u] as usize;
            let ev = if any_goal {
                w.ev[f] - w.goal_ev[u]
            } else {
                w.ev[f]
            };
            let r = if depends { w.reward[u] } else { reward };
            *o = r + gamma * ev;
        }
    }

    /// Per block: the active block cores at the state's segments `seg`, the mixed rows (one
    /// per block action, entries in increasing block core, zero weights left out, columns
    /// local to the support) and their support with its grid offsets.
    fn mix_blocks(&self, seg: &[Segment<T>; MAX_DIMS], w: &mut QWork<T>) {
        for (b, t) in self.tables.iter().enumerate() {
            let mut bseg = *seg;
            for (s, &d) in bseg.iter_mut().zip(&t.dims) {
                *s = seg[d];
            }
            w.act.clear();
            for_each_core(&bseg[..t.dims.len()], |idx, mu| {
                let c = idx
                    .iter()
                    .zip(&t.strides)
                    .map(|(i, s)| i * s)
                    .sum::<usize>();
                w.act.push((c, mu));
            });
            let rows = &mut w.mixed[b];
            rows.clear();
            let support = &mut w.support[b];
            support.clear();
            for a in 0..t.n_actions {
                w.hit.clear();
                for &(c, mu) in &w.act {
                    let (cols, ws) = t.row(c, a);
                    for (&k, &wk) in cols.iter().zip(ws) {
                        let k = k as usize;
                        if !w.touched[k] {
                            w.touched[k] = true;
                            w.dense[k] = T::ZERO;
                            w.hit.push(k as u32);
                        }
                        w.dense[k] += mu * wk;
                    }
                }
                w.hit.sort_unstable();
                for &k in &w.hit {
                    let k = k as usize;
                    w.touched[k] = false;
                    if !w.in_support[k] {
                        w.in_support[k] = true;
                        support.push(k as u32);
                    }
                    if w.dense[k] != T::ZERO {
                        rows.col.push(k as u32);
                        rows.weight.push(w.dense[k]);
                    }
                }
                rows.ptr.push(rows.col.len() as u32);
            }
            support.sort_unstable();
            let local = &mut w.local[b];
            let offsets = &mut w.grid_offset[b];
            offsets.clear();
            for (i, &k) in support.iter().enumerate() {
                w.in_support[k as usize] = false;
                local[k as usize] = i as u32;
                offsets.push(t.grid_offset[k as usize]);
            }
            for k in &mut rows.col {
                *k = local[*k as usize];
            }
        }
    }

    /// Copies the box of `V` over the blocks' supports into `w.vbox`, blocks in gather order
    /// (the block of the largest grid strides slowest, the innermost block's values
    /// contiguous), an inner row at a time, the outer blocks' combinations visited like an
    /// odometer; returns the supports' sizes in gather order.
    fn gather_box(&self, v: &[T], w: &mut QWork<T>) -> [usize; MAX_DIMS] {
        let nb = self.tables.len();
        let order = &self.q.gather_order;
        let inner = order[nb - 1];
        let mut sizes = [0usize; MAX_DIMS];
        let mut stride = [0usize; MAX_DIMS];
        let mut box_len = 1;
        for l in (0..nb).rev() {
            sizes[l] = w.support[order[l]].len();
            stride[l] = box_len;
            box_len *= sizes[l];
        }
        w.vbox.resize(box_len + INPUT_PAD, T::ZERO);
        // Copied an inner row at a time, the outer blocks' combinations visited like an
        // odometer.
        {
            let inner_off = &w.grid_offset[inner];
            let span = inner_off.iter().max().map_or(0, |&o| o + 1);
            let mut digit = [0usize; MAX_DIMS];
            let mut g: usize = order[..nb - 1].iter().map(|&b| w.grid_offset[b][0]).sum();
            'combos: for dst in w.vbox[..box_len].chunks_exact_mut(sizes[nb - 1]) {
                let src = &v[g..g + span];
                for (d, &gi) in dst.iter_mut().zip(inner_off) {
                    *d = src[gi];
                }
                let mut l = nb - 1;
                loop {
                    if l == 0 {
                        break 'combos;
                    }
                    l -= 1;
                    let off = &w.grid_offset[order[l]];
                    g -= off[digit[l]];
                    digit[l] += 1;
                    if digit[l] < sizes[l] {
                        g += off[digit[l]];
                        break;
                    }
                    digit[l] = 0;
                    g += off[0];
                }
            }
        }
        sizes
    }

    /// Contracts the box `vbox` (block supports of `sizes`, blocks in gather order, the
    /// first slowest) with `rows` (per block in table order, one row per block action, local
    /// columns) into `out`, `[a_0][a_1]..` over the blocks in gather order; `tmp` is scratch.
    ///
    /// Stage `l` maps `[p][k][r]` to `[p][a][r]` (`p` over the earlier blocks' actions, `r`
    /// over the later blocks' support cores), one [`Kernels::stage`] call per `p`: every
    /// element is `sum_e w_e in[p][k_e][r]` over the row's entries in order, with fused
    /// multiply-adds from 0, so the result is the same on every kernel instance.
    fn contract_box(
        &self,
        rows: &[LocalRows<T>],
        sizes: &[usize],
        vbox: &[T],
        out: &mut Vec<T>,
        tmp: &mut Vec<T>,
    ) {
        let nb = sizes.len();
        let mut r: usize = sizes.iter().product();
        let mut p = 1usize;
        // Stages alternate between `out` and `tmp` so that the last one writes `out`; both
        // keep `INPUT_PAD` spare elements so that every kernel instance loads whole vectors.
        let (mut dst, mut src) = if nb % 2 == 1 {
            (&mut *out, &mut *tmp)
        } else {
            (&mut *tmp, &mut *out)
        };
        for (l, &k) in sizes.iter().enumerate() {
            let b = self.q.gather_order[l];
            let a = self.tables[b].n_actions;
            r /= k;
            dst.resize(p * a * r + INPUT_PAD, T::ZERO);
            let input: &[T] = if l == 0 { vbox } else { src };
            let view = rows[b].view(k);
            for (i, o) in dst[..p * a * r].chunks_exact_mut(a * r).enumerate() {
                // The chunk's own spare elements are the next chunks' (or the padding).
                self.kernels.stage(view, 0, a, 1, r, &input[i * k * r..], o);
            }
            p *= a;
            core::mem::swap(&mut dst, &mut src);
        }
    }
}

/// Sparse rows with columns local to a box (positions in a block's support).
#[derive(Default)]
pub(super) struct LocalRows<T> {
    ptr: Vec<u32>,
    col: Vec<u32>,
    weight: Vec<T>,
}

impl<T: Real> LocalRows<T> {
    /// The rows as the kernels take them, over `n_cols` local columns.
    fn view(&self, n_cols: usize) -> Rows<'_, T> {
        Rows::checked(&self.ptr, &self.col, &self.weight, n_cols)
            .expect("local rows hold memberships over their box's support")
    }

    /// No rows (ready for the first row's entries).
    fn clear(&mut self) {
        self.ptr.clear();
        self.ptr.push(0);
        self.col.clear();
        self.weight.clear();
    }
}

/// Buffers of [`BlockOperator::q_values`], kept between calls.
pub(super) struct QWork<T> {
    /// Per block: the mixed rows.
    mixed: Vec<LocalRows<T>>,
    /// Per block: one core's rows (goal and terminal corrections).
    pure: Vec<LocalRows<T>>,
    /// Per block: the support of the mixed rows (block cores, increasing).
    support: Vec<Vec<u32>>,
    /// Per block and block core: its position in the support (support cores only).
    local: Vec<Vec<u32>>,
    /// Per block: the grid offsets of the support cores.
    grid_offset: Vec<Vec<usize>>,
    /// One block's active block cores and memberships.
    act: Vec<(usize, T)>,
    /// The block cores one mixed row touches.
    hit: Vec<u32>,
    /// One mixed row, dense over a block's cores (entries of `hit` only).
    dense: Vec<T>,
    /// Per block core: in `hit` (all false between rows).
    touched: Vec<bool>,
    /// Per block core: in the support (all false between blocks).
    in_support: Vec<bool>,
    /// The box of `V`.
    vbox: Vec<T>,
    /// The active cores: (internal index, membership).
    cores: Vec<(usize, T)>,
    /// The mixed rows' expectations, `[a_0][a_1]..`.
    ev: Vec<T>,
    /// Contraction scratch.
    tmp: Vec<T>,
    /// One core's expectations, `[a_0][a_1]..`.
    ev_core: Vec<T>,
    /// Per joint action: the mixed reward (action-dependent rewards).
    reward: Vec<T>,
    /// Per joint action: the expectations to take back out.
    goal_ev: Vec<T>,
    /// Per joint action: whether one core's expectation drops out.
    drop: Vec<bool>,
    /// Active cores with a goal or terminal correction: (internal index, membership).
    corrections: Vec<(usize, T)>,
    /// A core's state.
    x: Vec<T>,
    /// A joint action vector.
    u: Vec<T>,
}

/// Calls `f(idx, mu)` for every combination of the cores of `segs` (one segment per
/// variable): `idx` holds each variable's core, `mu` the product of the memberships. The
/// visit order (increasing row-major index) and the products (the split variables'
/// memberships multiplied in variable order from 1) are those of
/// [`crate::partition::ActiveCores::for_each`], so the weights are bit-identical.
fn for_each_core<T: Real>(segs: &[Segment<T>], mut f: impl FnMut(&[usize], T)) {
    let mut split = [0usize; MAX_DIMS];
    let mut s = 0;
    let mut idx = [0usize; MAX_DIMS];
    for (e, sg) in segs.iter().enumerate() {
        idx[e] = sg.lower;
        if sg.is_split() {
            split[s] = e;
            s += 1;
        }
    }
    for mask in 0..(1usize << s) {
        let mut mu = T::ONE;
        for (j, &e) in split[..s].iter().enumerate() {
            let sg = &segs[e];
            if (mask >> (s - 1 - j)) & 1 == 1 {
                idx[e] = sg.lower + 1;
                mu *= sg.upper_weight;
            } else {
                idx[e] = sg.lower;
                mu *= sg.lower_weight();
            }
        }
        f(&idx[..segs.len()], mu);
    }
}

/// What a controller needs to take the greedy decisions of [`Operator::q_values`] without
/// the model: the block path's tables, the map from joint actions to their block actions, the
/// discount and the per-core rewards ([`Operator::decision_tables`]; written into an exported
/// policy by `fuzzyq export --greedy` and read by [`crate::view::PolicyView::q_values`]).
#[derive(Clone, Debug, PartialEq)]
pub struct DecisionTables<T> {
    /// The discount `gamma`.
    pub gamma: T,
    /// The blocks in contraction order: the block of the largest grid strides first.
    pub blocks: Vec<DecisionBlock<T>>,
    /// Per joint action: its position in the contraction's result, `[a_0][a_1]..` over the
    /// blocks in contraction order (the first slowest).
    pub q_index: Vec<u32>,
    /// `rho(x_d)` per core, row-major grid order.
    pub rewards: Vec<T>,
}

/// One block of [`DecisionTables`]: its transition rows over block cores, numbered row-major
/// over [`Self::dims`] (the last fastest).
#[derive(Clone, Debug, PartialEq)]
pub struct DecisionBlock<T> {
    /// The block's state variables, increasing.
    pub dims: Vec<u32>,
    /// Block actions (rows per block core).
    pub n_actions: u32,
    /// Row `c * n_actions + a` holds entries `ptr[i]..ptr[i + 1]` of `col` and `weight`.
    pub ptr: Vec<u32>,
    /// Successor block core of each entry, increasing within a row.
    pub col: Vec<u32>,
    /// Successor membership of each entry.
    pub weight: Vec<T>,
    /// The most block cores the rows of one state's active block cores reach, over every
    /// state: the bound a decision's buffers are sized by.
    pub max_support: u32,
}

impl<T: Real> BlockOperator<T> {
    /// See [`Operator::decision_tables`].
    pub(in crate::solver) fn decision_tables<M: Model<T> + Sync + ?Sized>(
        &self,
        op: &Operator<'_, T, M>,
    ) -> Result<DecisionTables<T>, SolveError> {
        let refuse = |why| Err(SolveError::NoDecisionTables { why });
        if self.terminals.is_some() {
            return refuse("the model has terminal states");
        }
        if op.backup.absorbing_goal {
            return refuse("the backup has an absorbing goal");
        }
        let Some(internal_rewards) = op
            .rewards
            .as_deref()
            .filter(|_| !op.model.reward_depends_on_action())
        else {
            return refuse("the reward depends on the action");
        };
        let mut rewards = vec![T::ZERO; internal_rewards.len()];
        for (i, &r) in internal_rewards.iter().enumerate() {
            rewards[self.to_grid_index(i)] = r;
        }
        let blocks = self
            .q
            .gather_order
            .iter()
            .map(|&b| {
                let t = &self.tables[b];
                let rows = t.rows.view();
                let n_rows = rows.n_rows();
                let (mut ptr, mut col, mut weight) = (vec![0u32], Vec::new(), Vec::new());
                for i in 0..n_rows {
                    let (c, w) = rows.row(i);
                    col.extend_from_slice(c);
                    weight.extend_from_slice(w);
                    ptr.push(col.len() as u32);
                }
                DecisionBlock {
                    dims: t.dims.iter().map(|&d| d as u32).collect(),
                    n_actions: t.n_actions as u32,
                    ptr,
                    col,
                    weight,
                    max_support: max_support(t, op) as u32,
                }
            })
            .collect();
        Ok(DecisionTables {
            gamma: op.gamma,
            blocks,
            q_index: self.q.q_index.clone(),
            rewards,
        })
    }
}

/// The most block cores that the rows of the active block cores of one state reach, over every
/// state: per cell of the block's grid (each variable's lower core, and the next one if there
/// is one), the union of its corner cores' rows over every block action.
fn max_support<T: Real, M: ?Sized>(t: &BlockTable<T>, op: &Operator<'_, T, M>) -> usize {
    let counts: Vec<usize> = t.dims.iter().map(|&d| op.grid.dim(d).n_cores()).collect();
    let mut seen = vec![usize::MAX; t.n_cores];
    let mut best = 0;
    for cell in 0..t.n_cores {
        let mut n = 0;
        let k = counts.len();
        for corner in 0..(1usize << k) {
            let mut c = 0;
            let mut inside = true;
            for (j, (&count, &stride)) in counts.iter().zip(&t.strides).enumerate() {
                let lower = (cell / stride) % count;
                let i = lower + ((corner >> j) & 1);
                inside &= i < count;
                c += i * stride;
            }
            if !inside {
                continue;
            }
            for a in 0..t.n_actions {
                for &s in t.row(c, a).0 {
                    if seen[s as usize] != cell {
                        seen[s as usize] = cell;
                        n += 1;
                    }
                }
            }
        }
        best = best.max(n);
    }
    best
}
