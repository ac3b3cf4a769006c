//! Unit tests of the block operator (`block.rs`): the decision path against a reference
//! written the straightforward way (fresh buffers, the whole box of `V` materialised, the
//! stages of the scalar kernel).

use super::*;
use crate::action::ActionSet;
use crate::backup::Backup;
use crate::model::Block;
use crate::solver::Kernel;
use crate::solver::simd::{Rows, select_real};
use crate::solver::{BackupPath, Path};

/// Compressed rows of `(block core, weight)` entries, with block cores renumbered by `local`.
fn local_rows<T: Real, R: Iterator<Item = (usize, T)>>(
    rows: impl Iterator<Item = R>,
    local: &[u32],
) -> (Vec<u32>, Vec<u32>, Vec<T>) {
    let mut ptr = vec![0u32];
    let mut col = Vec::new();
    let mut weight = Vec::new();
    for row in rows {
        for (k, w) in row {
            col.push(local[k]);
            weight.push(w);
        }
        ptr.push(col.len() as u32);
    }
    (ptr, col, weight)
}

/// `Q(x, .)` by the definition of [`BlockOperator::q_values`], written plainly: fresh buffers,
/// the whole box materialised by its product index, the scalar kernel's stages in the
/// `[k][r][p]` layout, rewards from the model at each active core.
fn reference<T: Real, M: Model<T> + Sync + ?Sized>(
    blk: &BlockOperator<T>,
    op: &Operator<'_, T, M>,
    v: &[T],
    x: &[T],
    out: &mut [T],
) -> Result<(), SolveError> {
    let grid = &op.grid;
    let active = grid.active(x)?;
    let nb = blk.tables.len();

    // Per block: active block cores with memberships, the mixed rows and their support.
    struct Mixed<T> {
        support: Vec<usize>,
        /// Block core -> position in `support`.
        local: Vec<u32>,
        ptr: Vec<u32>,
        col: Vec<u32>,
        weight: Vec<T>,
    }
    let mut mixed: Vec<Mixed<T>> = Vec::with_capacity(nb);
    for t in &blk.tables {
        let sub = sub_partition(grid, &t.dims);
        let xs: Vec<T> = t.dims.iter().map(|&d| x[d]).collect();
        let mut act = Vec::new();
        sub.active_unchecked(&xs).for_each(|c, w| act.push((c, w)));
        let mut dense = vec![T::ZERO; t.n_cores];
        let mut touched = vec![false; t.n_cores];
        let mut rows: Vec<Vec<(usize, T)>> = Vec::with_capacity(t.n_actions);
        for a in 0..t.n_actions {
            dense.fill(T::ZERO);
            let mut hit = Vec::new();
            for &(c, mu) in &act {
                let (cols, ws) = t.row(c, a);
                for (&k, &w) in cols.iter().zip(ws) {
                    if !hit.contains(&(k as usize)) {
                        hit.push(k as usize);
                    }
                    dense[k as usize] += mu * w;
                }
            }
            hit.sort_unstable();
            for &k in &hit {
                touched[k] = true;
            }
            rows.push(hit.iter().map(|&k| (k, dense[k])).collect());
        }
        let support: Vec<usize> = (0..t.n_cores).filter(|&k| touched[k]).collect();
        let mut local = vec![u32::MAX; t.n_cores];
        for (i, &k) in support.iter().enumerate() {
            local[k] = i as u32;
        }
        let (ptr, col, weight) = local_rows(rows.iter().map(|r| r.iter().copied()), &local);
        mixed.push(Mixed {
            support,
            local,
            ptr,
            col,
            weight,
        });
    }

    // The box of V over the supports, blocks in gather order with the first slowest.
    let order = blk.q.gather_order.clone();
    let box_len: usize = mixed.iter().map(|m| m.support.len()).product();
    let mut vbox = vec![T::ZERO; box_len];
    let mut idx = vec![0usize; nb];
    for slot in vbox.iter_mut() {
        let g: usize = (0..nb)
            .map(|l| {
                let b = order[l];
                blk.tables[b].grid_offset[mixed[b].support[idx[l]]]
            })
            .sum();
        *slot = v[g];
        for l in (0..nb).rev() {
            idx[l] += 1;
            if idx[l] < mixed[order[l]].support.len() {
                break;
            }
            idx[l] = 0;
        }
    }

    // Contract the box with the given rows (one row per block action for each block), the
    // blocks in gather order, with the scalar kernel's stage: `[k][r][p]` to `[r][a][p]`, so
    // the result is `[a_last]..[a_first]`.
    let kernels = select_real::<T>(Some(Kernel::Scalar)).unwrap();
    let contract_box = |rows: &dyn Fn(usize) -> (Vec<u32>, Vec<u32>, Vec<T>)| -> Vec<T> {
        let mut input = vbox.clone();
        let mut p = 1usize;
        for l in 0..nb {
            let b = order[l];
            let k = mixed[b].support.len();
            let r: usize = order[l + 1..]
                .iter()
                .map(|&b| mixed[b].support.len())
                .product();
            let a = blk.tables[b].n_actions;
            let (ptr, col, weight) = rows(b);
            let mut out = vec![T::ZERO; r * a * p];
            let rows = Rows::checked(&ptr, &col, &weight, k).expect("memberships over the box");
            kernels.stage(rows, 0, a, r, p, &input, &mut out);
            input = out;
            p *= a;
        }
        input
    };
    // Position of joint action `u` in the result.
    let position = |u: usize| {
        let prod = blk.product_index(u);
        let (mut pos, mut scale) = (0, 1);
        for &b in &order {
            let n = blk.tables[b].n_actions;
            pos += (prod / blk.p_len[b]) % n * scale;
            scale *= n;
        }
        pos
    };
    let ev_mixed = contract_box(&|b| {
        let m = &mixed[b];
        (m.ptr.clone(), m.col.clone(), m.weight.clone())
    });

    // Rewards of the active cores, and the expectations of goal cores and of transitions
    // into terminal states, to take back out (per joint action).
    let e = op.state_dim();
    let mj = op.joint.n_joint();
    let mut xd = vec![T::ZERO; e];
    let mut uvec = vec![T::ZERO; op.joint.dim()];
    let mut reward_mix = vec![T::ZERO; mj];
    let mut goal_ev = vec![T::ZERO; mj];
    let mut any_goal = false;
    let mut succ = vec![T::ZERO; e];
    let mut drop = vec![false; mj];
    let depends = op.model.reward_depends_on_action();
    let mut cores = Vec::new();
    active.for_each(|d, mu| cores.push((d, mu)));
    for &(d, mu) in &cores {
        grid.core_state(d, &mut xd)?;
        if depends {
            for (u, r) in reward_mix.iter_mut().enumerate() {
                op.joint.vector_unchecked(u, &mut uvec);
                *r += mu * op.model.reward(&xd, &uvec);
            }
        } else {
            op.joint.vector_unchecked(0, &mut uvec);
            let rd = op.model.reward(&xd, &uvec);
            for r in reward_mix.iter_mut() {
                *r += mu * rd;
            }
        }
        let goal = op.backup.absorbing_goal && op.model.is_goal(&xd);
        if goal || blk.terminals.is_some() {
            // This core's block cores, to contract its pure rows.
            let block_cores: Vec<usize> = blk
                .tables
                .iter()
                .map(|t| {
                    let sub = sub_partition(grid, &t.dims);
                    let xs: Vec<T> = t.dims.iter().map(|&dd| xd[dd]).collect();
                    let mut c = 0;
                    sub.active_unchecked(&xs).for_each(|k, _| c = k);
                    c
                })
                .collect();
            // The joint actions whose expectation drops out: all of them at a goal core,
            // else those leading to a terminal state.
            let mut any = goal;
            for (u, d) in drop.iter_mut().enumerate() {
                *d = goal || {
                    blk.assemble_successor(&block_cores, u, &mut succ);
                    op.model.is_terminal(&succ)
                };
                any |= *d;
            }
            if !any {
                continue;
            }
            any_goal = true;
            let ev_d = contract_box(&|b| {
                let t = &blk.tables[b];
                let rows = (0..t.n_actions).map(|a| {
                    let (cols, ws) = t.row(block_cores[b], a);
                    cols.iter().map(|&k| k as usize).zip(ws.iter().copied())
                });
                local_rows(rows, &mixed[b].local)
            });
            for (u, g) in goal_ev.iter_mut().enumerate() {
                if drop[u] {
                    *g += mu * ev_d[position(u)];
                }
            }
        }
    }
    let gamma = op.gamma;
    for (u, o) in out.iter_mut().enumerate() {
        let p = position(u);
        let ev = if any_goal {
            ev_mixed[p] - goal_ev[u]
        } else {
            ev_mixed[p]
        };
        *o = reward_mix[u] + gamma * ev;
    }
    Ok(())
}

/// Point masses on the plane with one block per agent and axis (as `fuzzyq_sim`'s), with
/// options that exercise every branch of `q_values`.
struct Masses<T> {
    agents: usize,
    actions: Vec<T>,
    dims: Vec<[usize; 2]>,
    comps: Vec<[usize; 1]>,
    terminal: bool,
    action_reward: bool,
    /// A reward of these state variables alone (a smooth function of them), declared through
    /// `reward_depends_on_state` when the flag is set.
    reward_reads: Option<(Vec<usize>, bool)>,
}

impl<T: Real> Masses<T> {
    fn new(agents: usize, reversed: bool) -> Self {
        let levels = [-2.0, -0.5, 0.0, 0.5, 2.0];
        let mut actions = Vec::new();
        for &a in &levels {
            for &b in &levels {
                actions.extend([T::from_f64(a), T::from_f64(b)]);
            }
        }
        let mut dims = Vec::new();
        let mut comps = Vec::new();
        for i in 0..agents {
            for axis in 0..2 {
                dims.push([4 * i + axis, 4 * i + 2 + axis]);
                comps.push([2 * i + axis]);
            }
        }
        if reversed {
            // Blocks out of the joint action's radix order: a product-to-joint map.
            dims.reverse();
            comps.reverse();
        }
        Self {
            agents,
            actions,
            dims,
            comps,
            terminal: false,
            action_reward: false,
            reward_reads: None,
        }
    }

    fn grid(&self) -> Vec<Vec<T>> {
        let pos = [-6.0, -1.5, 0.0, 0.4, 6.0];
        let vel = [-3.0, 0.5, 3.0];
        (0..4 * self.agents)
            .map(|e| {
                let c: &[f64] = if e % 4 < 2 { &pos } else { &vel };
                c.iter().map(|&v| T::from_f64(v)).collect()
            })
            .collect()
    }
}

fn clamp<T: Real>(v: T, lim: f64) -> T {
    let l = T::from_f64(lim);
    if v > l {
        l
    } else if v < -l {
        -l
    } else {
        v
    }
}

impl<T: Real> Model<T> for Masses<T> {
    fn state_dim(&self) -> usize {
        4 * self.agents
    }
    fn n_agents(&self) -> usize {
        self.agents
    }
    fn action_set(&self, _agent: usize) -> ActionSet<'_, T> {
        ActionSet::try_new(&self.actions, 2).unwrap()
    }
    fn state_bounds(&self, dim: usize) -> (T, T) {
        let l = if dim % 4 < 2 { 6.0 } else { 3.0 };
        (T::from_f64(-l), T::from_f64(l))
    }
    fn step(&self, x: &[T], u: &[T], next: &mut [T]) {
        for i in 0..self.agents {
            for axis in 0..2 {
                let (p, v, f) = (x[4 * i + axis], x[4 * i + 2 + axis], u[2 * i + axis]);
                let c = |c: f64| T::from_f64(c);
                next[4 * i + 2 + axis] = clamp(c(0.7) * v + c(0.35) * f, 3.0);
                next[4 * i + axis] = clamp(p + c(0.4) * v + c(0.1) * f, 6.0);
            }
        }
    }
    fn reward(&self, x: &[T], u: &[T]) -> T {
        if let Some((reads, _)) = &self.reward_reads {
            return reads
                .iter()
                .map(|&d| T::from_f64(0.37 * (d + 1) as f64) * x[d] * x[d] + x[d])
                .sum();
        }
        let goal = if self.is_goal(x) {
            T::from_f64(5.0)
        } else {
            T::ZERO
        };
        if self.action_reward {
            goal - T::from_f64(0.01) * u.iter().map(|&a| a * a).sum::<T>()
        } else {
            goal
        }
    }
    fn reward_depends_on_action(&self) -> bool {
        self.action_reward
    }
    fn reward_depends_on_state(&self, dim: usize) -> bool {
        match &self.reward_reads {
            Some((reads, true)) => reads.contains(&dim),
            _ => true,
        }
    }
    fn is_goal(&self, x: &[T]) -> bool {
        x.iter().map(|&v| v * v).sum::<T>() < T::from_f64(0.5)
    }
    fn is_terminal(&self, x: &[T]) -> bool {
        x[0] > T::from_f64(5.0)
    }
    fn has_terminal_states(&self) -> bool {
        self.terminal
    }
    fn n_blocks(&self) -> usize {
        self.dims.len()
    }
    fn block(&self, b: usize) -> Block<'_> {
        Block {
            state_dims: &self.dims[b],
            action_components: &self.comps[b],
        }
    }
}

/// xorshift64: `n` values in `[lo, hi)`.
fn draws(n: usize, seed: u64, lo: f64, hi: f64) -> Vec<f64> {
    let mut s = seed | 1;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            lo + (hi - lo) * ((s >> 11) as f64 / (1u64 << 53) as f64)
        })
        .collect()
}

/// States: uniformly random (a little beyond the cores, to saturate), on cores, and
/// mixed (some variables on a core).
fn states<T: Real>(cores: &[Vec<T>], n: usize, seed: u64) -> Vec<Vec<T>> {
    let e = cores.len();
    let u = draws(n * e * 2, seed, 0.0, 1.0);
    (0..n)
        .map(|i| {
            (0..e)
                .map(|d| {
                    let c = &cores[d];
                    let (lo, hi) = (c[0].to_f64(), c[c.len() - 1].to_f64());
                    let r = u[(i * e + d) * 2];
                    let pick = u[(i * e + d) * 2 + 1];
                    let on_core = match i % 3 {
                        0 => false,
                        1 => true,
                        _ => pick < 0.5,
                    };
                    if on_core {
                        c[((pick * 7919.0) as usize) % c.len()]
                    } else {
                        T::from_f64(lo - 0.5 + (hi - lo + 1.0) * r)
                    }
                })
                .collect()
        })
        .collect()
}

/// Runs `f` on `m`'s grid and its block-path operator (`gamma = 0.9`).
fn on_block_path<T: Real, R>(
    m: &Masses<T>,
    absorbing: bool,
    f: impl FnOnce(ProductPartition<'_, T>, &Operator<'_, T, Masses<T>>) -> R,
) -> R {
    let cores = m.grid();
    let views: Vec<&[T]> = cores.iter().map(Vec::as_slice).collect();
    let grid = ProductPartition::try_new(&views).unwrap();
    let backup = Backup {
        gamma: T::from_f64(0.9),
        absorbing_goal: absorbing,
    };
    let op = Operator::new(m, grid, backup, BackupPath::Block).unwrap();
    f(grid, &op)
}

fn check<T: Real>(m: &Masses<T>, absorbing: bool, seed: u64) {
    on_block_path(m, absorbing, |grid, op| {
        let cores = m.grid();
        let Path::Block(blk) = &op.path else {
            panic!("the block path")
        };
        let mj = op.joint().n_joint();
        let v: Vec<T> = draws(grid.n_cores(), seed, -20.0, 100.0)
            .into_iter()
            .map(T::from_f64)
            .collect();
        let (mut fast, mut slow) = (vec![T::ZERO; mj], vec![T::ZERO; mj]);
        for x in states(&cores, 150, seed ^ 0x5DEE_CE66) {
            op.q_values(&v, &x, &mut fast).unwrap();
            reference(blk, op, &v, &x, &mut slow).unwrap();
            for (u, (a, b)) in fast.iter().zip(&slow).enumerate() {
                assert_eq!(
                    a.to_f64().to_bits(),
                    b.to_f64().to_bits(),
                    "{} agents, absorbing {absorbing}, action {u} at {x:?}: {a} vs {b}",
                    m.agents
                );
            }
        }
        assert!(
            op.q_values(
                &v,
                &cores.iter().map(|_| T::ZERO).collect::<Vec<_>>()[1..],
                &mut fast
            )
            .is_err()
        );
    });
}

/// The buffered `q_values` (gathered and contracted a row at a time, on the detected kernel)
/// gives the reference's bits: one and two agents,
/// blocks in and out of the joint radix order, absorbing goals, terminal states,
/// action-dependent rewards, both precisions.
#[test]
fn q_values_match_the_reference_bit_for_bit() {
    for agents in [1, 2] {
        for reversed in [false, true] {
            for (terminal, action_reward) in [(false, false), (true, false), (false, true)] {
                for absorbing in [false, true] {
                    let seed = 17 + agents as u64 * 101 + u64::from(reversed);
                    let mut m32 = Masses::<f32>::new(agents, reversed);
                    (m32.terminal, m32.action_reward) = (terminal, action_reward);
                    check(&m32, absorbing, seed);
                    let mut m64 = Masses::<f64>::new(agents, reversed);
                    (m64.terminal, m64.action_reward) = (terminal, action_reward);
                    check(&m64, absorbing, seed);
                }
            }
        }
    }
}

/// A full backup gives every core the maximum of its `Q` row: with the first stage in pieces
/// of 7 leading indices under test (`FIRST_STAGE_PIECE`), several per slab and a shorter last
/// one, every piece read from and written to its place. One and two agents (15 and 3,375
/// leading indices per slab), blocks in and out of the radix order.
#[test]
fn full_backups_in_first_stage_pieces_match_the_q_rows() {
    const { assert!(super::FIRST_STAGE_PIECE == 7) };
    for agents in [1, 2] {
        for reversed in [false, true] {
            let m = Masses::<f64>::new(agents, reversed);
            on_block_path(&m, false, |grid, op| {
                let v = draws(grid.n_cores(), 29 + agents as u64, -20.0, 100.0);
                let t = op.apply(&v).unwrap();
                let mut q = vec![0.0; op.joint().n_joint()];
                let mut x = vec![0.0; grid.n_dims()];
                for (i, &ti) in t.iter().enumerate() {
                    grid.core_state(i, &mut x).unwrap();
                    op.q_values(&v, &x, &mut q).unwrap();
                    let best = q.iter().fold(f64::NEG_INFINITY, |m, &y| m.max(y));
                    assert!(
                        (ti - best).abs() <= 1e-9 * (1.0 + best.abs()),
                        "{agents} agents, reversed {reversed}, core {i}: {ti} vs {best}"
                    );
                }
            });
        }
    }
}

/// A task's buffers hold one piece of the first stage, not the whole stage (15 and 3,375
/// leading indices per slab, 5 actions; pieces of 7 under test): every task of a
/// Gauss-Seidel sweep makes fresh buffers, and the whole stage's 1.8 MB on the paper grid
/// cost a sweep 12% of its time in page faults.
#[test]
fn task_buffers_hold_one_first_stage_piece() {
    for agents in [1, 2] {
        let m = Masses::<f32>::new(agents, false);
        on_block_path(&m, false, |_, op| {
            let Path::Block(blk) = &op.path else {
                panic!("the block path")
            };
            assert_eq!(blk.work(op).extra.scratch.len(), 7 * 5, "{agents} agents");
        });
    }
}

/// The first stage's `[a][r]` rows interleave into `[r][a]` at any output stride, on the
/// fixed-count paths (2 to 8 rows back to back) and the general one; padding is untouched.
#[test]
fn interleave_writes_every_value_once_in_place() {
    for na in 1..10 {
        for r in [1, 5, 37] {
            for r_stride in [na, na + 3, 16] {
                let src: Vec<f32> = (0..na * r).map(|i| i as f32).collect();
                let mut out = vec![-1.0f32; r * r_stride];
                super::super::simd::interleave(&src, na, (&mut out, r_stride));
                for (i, &x) in out.iter().enumerate() {
                    let (ri, a) = (i / r_stride, i % r_stride);
                    let want = if a < na { (a * r + ri) as f32 } else { -1.0 };
                    assert_eq!(x, want, "na {na}, r {r}, stride {r_stride}, at {i}");
                }
            }
        }
    }
}

/// The odometer's core states (`for_each_core_state`, from any first core) are the states
/// of `core_state`, and the tiled reorder agrees with the per-core index map both ways: two
/// agents (four blocks, one core per dimension pair), blocks in and out of the radix order.
#[test]
fn core_states_and_reorders_match_the_per_core_maps() {
    for reversed in [false, true] {
        let m = Masses::<f64>::new(2, reversed);
        on_block_path(&m, false, |grid, op| {
            let Path::Block(blk) = &op.path else {
                panic!("the block path")
            };
            let n = op.n_cores();
            let coords = op.block_coords();
            let mut want = vec![0.0; grid.n_dims()];
            for start in [0, 1, 14, 15, 224, n / 3, n - 1] {
                let mut x = vec![f64::NAN; grid.n_dims()];
                let mut next = start;
                op.for_each_core_state(&coords, start..n.min(start + 700), &mut x, |i, x| {
                    assert_eq!(i, next);
                    next += 1;
                    op.core_state(i, &mut want);
                    assert_eq!(x, &want[..], "core {i} from {start}, reversed {reversed}");
                });
            }
            let v: Vec<u32> = (0..n as u32).collect();
            let g = blk.reorder(&v, true);
            for (i, &x) in v.iter().enumerate() {
                assert_eq!(g[blk.to_grid_index(i)], x, "to grid, core {i}");
            }
            assert_eq!(blk.reorder(&g, false), v, "back to internal order");
            // Placed a few slabs at a time, in any order: the same grid order.
            let (slab, slabs) = (blk.slab_len(), blk.n_slabs());
            let placer = blk.slab_placer();
            for per in [1, 2, 3, slabs] {
                let mut pieced = vec![u32::MAX; n];
                let firsts: Vec<usize> = (0..slabs).step_by(per).collect();
                for &s0 in firsts.iter().rev() {
                    let end = (s0 + per).min(slabs);
                    placer.place(s0, &v[s0 * slab..end * slab], &mut pieced);
                }
                assert_eq!(pieced, g, "pieces of {per} slabs, reversed {reversed}");
            }
            // Eight-byte values (`f64` values) take the other word of the scattered stores.
            let v64: Vec<u64> = v.iter().map(|&x| u64::from(x) << 32 | 7).collect();
            let g64: Vec<u64> = g.iter().map(|&x| u64::from(x) << 32 | 7).collect();
            let mut pieced = vec![u64::MAX; n];
            for s0 in (0..slabs).step_by(2) {
                let end = (s0 + 2).min(slabs);
                placer.place(s0, &v64[s0 * slab..end * slab], &mut pieced);
            }
            assert_eq!(pieced, g64, "eight-byte values, reversed {reversed}");
        });
    }
}

/// A reward that declares the state variables it ignores is evaluated once per class of
/// cores that agree on the others and copied to the rest (`rewards_by_class`): the rewards
/// and bound of an evaluation at every core, bit for bit, one and two agents, blocks in and
/// out of the radix order, none to all but one of the variables read.
#[test]
fn rewards_by_class_are_the_rewards_of_every_core() {
    for (agents, reversed) in [(1, false), (2, false), (2, true)] {
        let e = 4 * agents;
        for reads in [
            vec![],
            vec![0],
            vec![0, 1],
            vec![2, 3],
            vec![0, 1, 4, 5],
            vec![1, 2, 3, 6, 7],
        ] {
            if reads.iter().any(|&d| d >= e) {
                continue;
            }
            let rewards = |declared: bool| {
                let mut m = Masses::<f32>::new(agents, reversed);
                m.reward_reads = Some((reads.clone(), declared));
                on_block_path(&m, false, |_, op| {
                    let mut out = vec![0.0f32; op.n_cores()];
                    let pooled = op.rewards_by_class(&op.block_coords(), &mut out);
                    assert_eq!(pooled.is_some(), declared, "reads {reads:?}");
                    let bits: Vec<u32> = op
                        .rewards
                        .as_ref()
                        .unwrap()
                        .iter()
                        .map(|r| r.to_bits())
                        .collect();
                    (bits, op.reward_bound)
                })
            };
            assert_eq!(
                rewards(true),
                rewards(false),
                "{agents} agents, reads {reads:?}, reversed {reversed}"
            );
        }
    }
    // A reward that reads every variable is evaluated at every core.
    let mut m = Masses::<f32>::new(1, false);
    m.reward_reads = Some(((0..4).collect(), true));
    on_block_path(&m, false, |_, op| {
        let mut out = vec![0.0f32; op.n_cores()];
        assert!(op.rewards_by_class(&op.block_coords(), &mut out).is_none());
    });
}
