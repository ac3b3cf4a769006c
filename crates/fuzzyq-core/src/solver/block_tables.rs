//! Building the block operator's tables: the sub-grids over each block's state variables,
//! the block declarations checked, the block actions, and each block's transition rows,
//! given by the model or found by stepping it (each successor checked against other contexts).

use std::vec::Vec;

use super::super::SolveError;
use super::super::simd::RowsBuf;
use super::BlockTable;
use crate::action::JointActions;
use crate::model::Model;
use crate::partition::{MAX_DIMS, Partition, ProductPartition};
use crate::real::Real;

/// Sub-partition over a block's state variables.
pub(super) fn sub_partition<'a, T: Real>(
    grid: &ProductPartition<'a, T>,
    dims: &[usize],
) -> ProductPartition<'a, T> {
    let mut parts = [grid.dim(0); MAX_DIMS];
    for (p, &e) in parts.iter_mut().zip(dims) {
        *p = grid.dim(e);
    }
    let parts: &[Partition<'a, T>] = &parts[..dims.len()];
    ProductPartition::from_partitions(parts).expect("a block of a valid grid is a valid grid")
}

/// The row-major grid offset of every core of `sub`, the sub-grid over `dims`.
fn grid_offsets<T: Real>(
    sub: &ProductPartition<'_, T>,
    grid: &ProductPartition<'_, T>,
    dims: &[usize],
) -> Result<Vec<usize>, SolveError> {
    let mut idx = vec![0usize; dims.len()];
    (0..sub.n_cores())
        .map(|c| {
            sub.unravel(c, &mut idx)?;
            Ok(dims
                .iter()
                .zip(&idx)
                .map(|(&d, &i)| i * grid.strides()[d])
                .sum())
        })
        .collect()
}

/// A block table the model gives directly ([`Model::block_rows`]), checked and with its rows
/// reordered to the operator's block actions `tuples`; with the cores' grid offsets.
pub(super) fn given_rows<T: Real>(
    given: &crate::model::BlockRows<'_, T>,
    comps: &[usize],
    tuples: &[Vec<T>],
    sub: &ProductPartition<'_, T>,
    grid: &ProductPartition<'_, T>,
    dims: &[usize],
) -> Result<(RowsBuf<T>, Vec<usize>), &'static str> {
    let n_cores = sub.n_cores();
    let k = comps.len();
    if given.actions.len() != given.n_actions * k {
        return Err("its table's action values do not match its action count");
    }
    if given.ptr.len() != n_cores * given.n_actions + 1 {
        return Err("its table does not have one row per (block core, block action)");
    }
    // Operator block action -> the table's block action.
    let mut order = Vec::with_capacity(tuples.len());
    for t in tuples {
        let found = (0..given.n_actions).find(|&a| given.actions[a * k..(a + 1) * k] == t[..]);
        order.push(found.ok_or("its table has no row for a value the joint actions give it")?);
    }
    let (mut ptr, mut col, mut weight) = (vec![0u32], Vec::new(), Vec::new());
    for c in 0..n_cores {
        for &a in &order {
            let row = c * given.n_actions + a;
            let (lo, hi) = (given.ptr[row] as usize, given.ptr[row + 1] as usize);
            if lo > hi || hi > given.col.len() || given.col.len() != given.weight.len() {
                return Err("its table's row starts are not increasing within its entries");
            }
            let mut sum = 0.0;
            for (&kc, &w) in given.col[lo..hi].iter().zip(&given.weight[lo..hi]) {
                if kc as usize >= n_cores || !w.is_finite() || w < T::ZERO {
                    return Err("its table has an entry outside the block's cores or a \
                                negative or non-finite weight");
                }
                sum += w.to_f64();
                col.push(kc);
                weight.push(w);
            }
            if (sum - 1.0).abs() > 1e-4 {
                return Err("a row of its table does not sum to 1");
            }
            ptr.push(u32::try_from(col.len()).map_err(|_| "its table is too large")?);
        }
    }
    let rows = RowsBuf::new(ptr, col, weight, n_cores)
        .ok_or("its table is malformed")?
        .with_groups(order.len());
    let offsets = grid_offsets(sub, grid, dims).map_err(|_| "its cores do not fit the grid")?;
    Ok((rows, offsets))
}

/// The values of `dims` in `x`.
fn x_block<T: Real>(x: &[T], dims: &[usize]) -> Vec<T> {
    dims.iter().map(|&d| x[d]).collect()
}

/// Checks `model`'s block declarations against a state of `e` variables and joint actions of
/// `a_dim` components: every block names some variables, all within the state, and action
/// components within the joint action; every variable belongs to exactly one block.
pub(super) fn check_blocks<T: Real, M: Model<T> + ?Sized>(
    model: &M,
    e: usize,
    a_dim: usize,
) -> Result<(), SolveError> {
    let nb = model.n_blocks();
    let mut count = vec![0usize; e];
    for b in 0..nb {
        let block = model.block(b);
        if block.state_dims.is_empty() {
            return Err(SolveError::BlockDeclaration {
                block: b,
                reason: "it has no state variables",
            });
        }
        for &d in block.state_dims {
            if d >= e {
                return Err(SolveError::BlockDeclaration {
                    block: b,
                    reason: "it names a state variable beyond the state's length",
                });
            }
            count[d] += 1;
        }
        if block.action_components.iter().any(|&c| c >= a_dim) {
            return Err(SolveError::BlockDeclaration {
                block: b,
                reason: "it names an action component beyond the joint action's length",
            });
        }
    }
    if let Some(dim) = count.iter().position(|&c| c != 1) {
        return Err(SolveError::BlockCoverage {
            dim,
            count: count[dim],
        });
    }

    Ok(())
}

/// The distinct tuples of action components `comps` over every joint action of `joint`, in
/// order of first appearance; `block_action[u]` is joint action `u`'s tuple.
pub(super) fn action_tuples<T: Real>(
    joint: &JointActions<'_, T>,
    comps: &[usize],
    block_action: &mut [u32],
) -> Vec<Vec<T>> {
    let mut uvec = vec![T::ZERO; joint.dim()];
    let mut tuples: Vec<Vec<T>> = Vec::new();
    for (u, slot) in block_action.iter_mut().enumerate() {
        joint.vector_unchecked(u, &mut uvec);
        let t: Vec<T> = comps.iter().map(|&c| uvec[c]).collect();
        let a = match tuples.iter().position(|x| *x == t) {
            Some(a) => a,
            None => {
                tuples.push(t);
                tuples.len() - 1
            }
        };
        *slot = a as u32;
    }
    tuples
}

/// Block `b`'s table by stepping `model` from every block core under every block action
/// (`tuples` of components `comps`), the other variables and components held at their first
/// values; each successor is checked against three other contexts (the last cores and joint
/// action, the middle ones, and a mix varying with the row): a block whose successor depends
/// on anything outside it is refused ([`SolveError::BlockMismatch`]).
#[allow(clippy::too_many_arguments)] // the block and where it sits
pub(super) fn stepped_table<T: Real, M: Model<T> + Sync + ?Sized>(
    model: &M,
    grid: &ProductPartition<'_, T>,
    joint: &JointActions<'_, T>,
    b: usize,
    dims: Vec<usize>,
    comps: &[usize],
    tuples: &[Vec<T>],
    sub: &ProductPartition<'_, T>,
) -> Result<BlockTable<T>, SolveError> {
    let e = grid.n_dims();
    let m = joint.n_joint();
    let terminal = model.has_terminal_states();
    let (n_cores, n_actions) = (sub.n_cores(), tuples.len());
    let mut base_u = vec![T::ZERO; joint.dim()];
    joint.vector_unchecked(0, &mut base_u);
    let base_x: Vec<T> = grid.dims().iter().map(|p| p.first()).collect();
    // Check contexts: (core index of every variable, joint action), the third varying with
    // the row `r`.
    let context = |kind: usize, r: usize, x: &mut [T], u: &mut [T]| {
        for (e, (xe, p)) in x.iter_mut().zip(grid.dims()).enumerate() {
            let n = p.n_cores();
            let k = match kind {
                0 => n - 1,
                1 => n / 2,
                _ => (r * 7 + e * 5 + 3) % n,
            };
            *xe = p.cores()[k];
        }
        let ju = match kind {
            0 => m - 1,
            1 => m / 2,
            _ => (r * 31 + 17) % m,
        };
        joint.vector_unchecked(ju, u);
    };
    let mut alt_x = base_x.clone();
    let mut alt_u = base_u.clone();
    let mut ptr = Vec::with_capacity(n_cores * n_actions + 1);
    let mut col = Vec::new();
    let mut weight = Vec::new();
    let mut succ = Vec::new();
    ptr.push(0u32);
    let mut x = base_x.clone();
    let mut next = vec![T::ZERO; e];
    let mut next_alt = vec![T::ZERO; e];
    let mut sub_x = vec![T::ZERO; dims.len()];
    let mut ua = base_u.clone();
    let grid_offset = grid_offsets(sub, grid, &dims)?;
    for c in 0..n_cores {
        sub.core_state(c, &mut sub_x)?;
        for (&d, &v) in dims.iter().zip(&sub_x) {
            x[d] = v;
        }
        for (a, t) in tuples.iter().enumerate() {
            for (&comp, &v) in comps.iter().zip(t) {
                ua[comp] = v;
            }
            model.step(&x, &ua, &mut next);
            for (j, &d) in dims.iter().enumerate() {
                if !next[d].is_finite() {
                    return Err(SolveError::NonFinite { what: "successor" });
                }
                sub_x[j] = next[d];
            }
            if terminal {
                succ.extend_from_slice(&sub_x);
            }
            for kind in 0..3 {
                context(kind, c * n_actions + a, &mut alt_x, &mut alt_u);
                for (&d, &v) in dims.iter().zip(&x_block(&x, &dims)) {
                    alt_x[d] = v;
                }
                for (&comp, &v) in comps.iter().zip(t) {
                    alt_u[comp] = v;
                }
                model.step(&alt_x, &alt_u, &mut next_alt);
                if dims.iter().any(|&d| next[d] != next_alt[d]) {
                    return Err(SolveError::BlockMismatch { block: b });
                }
            }
            sub.active_unchecked(&sub_x).for_each(|k, w| {
                if w != T::ZERO {
                    col.push(k as u32);
                    weight.push(w);
                }
            });
            let len = u32::try_from(col.len()).map_err(|_| SolveError::TooLarge {
                what: "block transition table",
            })?;
            ptr.push(len);
        }
    }
    let rows = RowsBuf::new(ptr, col, weight, n_cores)
        .expect("rows are built with in-range columns")
        .with_groups(n_actions);
    Ok(BlockTable {
        dims,
        n_cores,
        n_actions,
        grid_offset,
        rows,
        succ,
        strides: sub.strides().to_vec(),
    })
}
