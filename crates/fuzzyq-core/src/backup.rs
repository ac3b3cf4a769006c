//! Backup kernels on caller-provided buffers.
//!
//! A fuzzy Q-iteration backup of core `d` under joint action `u` is
//! `theta[d, u] = rho(x_d, u) + gamma * V~(f(x_d, u))`, where `V~` interpolates the per-core
//! values `V[d'] = max_u theta[d', u]` with the memberships of the successor state. Two ways to
//! compute the expectation `V~(f(x_d, u))` live here:
//!
//! - the **generic** path, [`expected_values`]: step the model, find the successor's at most
//!   `2^E` active cores, sum (zero for a [terminal](Model::is_terminal) successor). Works for
//!   any model.
//! - the **block** path, [`contract`]: when the model declares independent dynamics blocks,
//!   the successor memberships factor into per-block tables and the expectation over all cores
//!   and joint actions is a sequence of small sparse products, one block at a time. The solver
//!   driver (`solver`, feature `std`) schedules these products; this function is one of them.
//!
//! [`q_values_from_v`] evaluates `Q(x, .)` at any state from `V` and the model: the greedy
//! policy of a solution that stores only `V`.

use crate::action::JointActions;
use crate::error::{EvalError, check_at_least, check_len};
use crate::model::Model;
use crate::partition::ProductPartition;
use crate::real::Real;

/// The backup's parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Backup<T> {
    /// Discount factor `gamma` in `[0, 1)`.
    pub gamma: T,
    /// Goal states ([`Model::is_goal`]) collect their reward and have zero future value.
    pub absorbing_goal: bool,
}

impl<T> Backup<T> {
    /// The plain discounted backup: discount `gamma`, no absorbing goal.
    #[must_use]
    pub const fn discounted(gamma: T) -> Self {
        Self {
            gamma,
            absorbing_goal: false,
        }
    }
}

/// Scratch length [`q_values_from_v`] needs: `2 E + A` for state length `E` and joint action
/// vector length `A`. [`expected_values`] and [`theta_row`] need `E + A`.
#[inline]
#[must_use]
pub const fn scratch_len(state_dim: usize, action_dim: usize) -> usize {
    2 * state_dim + action_dim
}

/// Generic path: `ev[u] = V~(f(x, u))` for every joint action `u` (`ev.len() == M`), and
/// `ev[u] = 0` when the successor is terminal ([`Model::is_terminal`], for a model that
/// [declares terminal states](Model::has_terminal_states)).
///
/// `scratch` needs `E + A` entries (see [`scratch_len`]). The successor states come from the
/// model, which must keep them finite; a non-finite successor is reported as an error (unless
/// the model calls it terminal: its value is not used then).
pub fn expected_values<T: Real, M: Model<T> + ?Sized>(
    model: &M,
    grid: &ProductPartition<'_, T>,
    joint: &JointActions<'_, T>,
    v: &[T],
    x: &[T],
    scratch: &mut [T],
    ev: &mut [T],
) -> Result<(), EvalError> {
    let e = grid.n_dims();
    check_len("state", e, x.len())?;
    check_len("V", grid.n_cores(), v.len())?;
    check_len("expected values", joint.n_joint(), ev.len())?;
    check_at_least("scratch", e + joint.dim(), scratch.len())?;
    let (next, rest) = scratch.split_at_mut(e);
    let uvec = &mut rest[..joint.dim()];
    let terminal = model.has_terminal_states();
    for (u, out) in ev.iter_mut().enumerate() {
        joint.vector_unchecked(u, uvec);
        model.step(x, uvec, next);
        *out = if terminal && model.is_terminal(next) {
            T::ZERO
        } else {
            grid.active(next)?.interpolate(v)
        };
    }
    Ok(())
}

/// `out[u] = Q(x, u) = sum_d mu_d(x) theta[d, u]` for the `joint` layout when only `V` is
/// stored: each active core's row is recomputed from the model,
/// `theta[d, u] = rho(x_d, u) + gamma V~(f(x_d, u))` (only `rho` for an absorbing goal core or
/// a terminal successor).
///
/// `row` (length `M`) and `scratch` ([`scratch_len`]) are work buffers. Cost: up to `2^E`
/// active cores times `M` model steps times `2^E` look-ups; the solver's block structure gives
/// a much faster equivalent for models that declare blocks.
#[allow(clippy::too_many_arguments)] // the inputs of a backup, spelled out; no natural grouping.
pub fn q_values_from_v<T: Real, M: Model<T> + ?Sized>(
    model: &M,
    grid: &ProductPartition<'_, T>,
    joint: &JointActions<'_, T>,
    v: &[T],
    backup: Backup<T>,
    x: &[T],
    scratch: &mut [T],
    row: &mut [T],
    out: &mut [T],
) -> Result<(), EvalError> {
    let e = grid.n_dims();
    let m = joint.n_joint();
    check_len("Q-values", m, out.len())?;
    check_len("row", m, row.len())?;
    check_at_least("scratch", scratch_len(e, joint.dim()), scratch.len())?;
    let active = grid.active(x)?;
    out.fill(T::ZERO);
    let (xd, rest) = scratch.split_at_mut(e);
    let mut result = Ok(());
    active.for_each(|d, w| {
        if result.is_err() {
            return;
        }
        // `d` is an active core of a validated grid, so `core_state` cannot fail.
        let _ = grid.core_state(d, xd);
        result = theta_row(model, grid, joint, v, backup, xd, rest, row);
        for (o, &t) in out.iter_mut().zip(row.iter()) {
            *o += w * t;
        }
    });
    result
}

/// `row[u] = theta[d, u]` for the core state `xd` (generic path); `scratch` needs `E + A`
/// entries.
#[allow(clippy::too_many_arguments)] // see q_values_from_v
pub fn theta_row<T: Real, M: Model<T> + ?Sized>(
    model: &M,
    grid: &ProductPartition<'_, T>,
    joint: &JointActions<'_, T>,
    v: &[T],
    backup: Backup<T>,
    xd: &[T],
    scratch: &mut [T],
    row: &mut [T],
) -> Result<(), EvalError> {
    let goal = backup.absorbing_goal && model.is_goal(xd);
    if goal {
        row.fill(T::ZERO);
    } else {
        expected_values(model, grid, joint, v, xd, scratch, row)?;
        for r in row.iter_mut() {
            *r *= backup.gamma;
        }
    }
    let uvec = &mut scratch[..joint.dim()];
    for (u, r) in row.iter_mut().enumerate() {
        joint.vector_unchecked(u, uvec);
        *r = model.reward(xd, uvec) + *r;
    }
    Ok(())
}

/// Sparse rows in compressed form: row `i` holds the entries `ptr[i]..ptr[i + 1]` of `col` and
/// `weight`. The block path stores, per block, one row per (block core, block action): the
/// memberships of the block's successor over the block's cores.
#[derive(Clone, Copy, Debug)]
pub struct SparseRows<'a, T> {
    /// Row starts, length `rows + 1`, non-decreasing, last equal to `col.len()`.
    pub ptr: &'a [u32],
    /// Column (successor block core) of each entry.
    pub col: &'a [u32],
    /// Weight (membership) of each entry.
    pub weight: &'a [T],
}

/// One stage of the block backup: contracts one block's successor cores against a tensor.
///
/// With `A` block actions, rows `first_row .. first_row + A` of `rows` (one per block action),
/// `input` laid out as `[k][r][p]` (`k` over the block's `K` successor cores, `r < r_len`,
/// `p < p_len`) and `out` as `[r][a][p]`:
///
/// `out[(r * A + a) * p_len + p] = sum_{(k, w) in row a} w * input[(k * r_len + r) * p_len + p]`
///
/// Entries are summed in row order, so the result does not depend on how callers split work.
/// A row without entries yields zeros.
#[allow(clippy::too_many_arguments)] // tensor shape parameters, spelled out.
pub fn contract<T: Real>(
    rows: SparseRows<'_, T>,
    first_row: usize,
    n_actions: usize,
    n_next: usize,
    r_len: usize,
    p_len: usize,
    input: &[T],
    out: &mut [T],
) -> Result<(), EvalError> {
    check_len("stage input", n_next * r_len * p_len, input.len())?;
    check_len("stage output", r_len * n_actions * p_len, out.len())?;
    check_at_least("sparse rows", first_row + n_actions + 1, rows.ptr.len())?;
    let lo = rows.ptr[first_row] as usize;
    let hi = rows.ptr[first_row + n_actions] as usize;
    check_at_least("sparse entries", hi, rows.col.len().min(rows.weight.len()))?;
    if let Some(bad) = rows.col[lo..hi].iter().find(|&&k| k as usize >= n_next) {
        return Err(EvalError::OutOfRange {
            what: "successor core",
            index: *bad as usize,
            len: n_next,
        });
    }
    for a in 0..n_actions {
        let (s, t) = (
            rows.ptr[first_row + a] as usize,
            rows.ptr[first_row + a + 1] as usize,
        );
        if s >= t {
            for r in 0..r_len {
                out[(r * n_actions + a) * p_len..][..p_len].fill(T::ZERO);
            }
            continue;
        }
        for r in 0..r_len {
            let o = &mut out[(r * n_actions + a) * p_len..][..p_len];
            let (k0, w0) = (rows.col[s] as usize, rows.weight[s]);
            let i0 = &input[(k0 * r_len + r) * p_len..][..p_len];
            for (y, &x) in o.iter_mut().zip(i0) {
                *y = w0 * x;
            }
            for e in s + 1..t {
                let (k, w) = (rows.col[e] as usize, rows.weight[e]);
                let i = &input[(k * r_len + r) * p_len..][..p_len];
                for (y, &x) in o.iter_mut().zip(i) {
                    *y += w * x;
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn contract_matches_definition() {
        // 2 actions, 3 successor cores, r_len 2, p_len 3.
        let ptr = [0u32, 2, 3];
        let col = [0u32, 2, 1];
        let weight = [0.25f64, 0.75, 1.0];
        let rows = SparseRows {
            ptr: &ptr,
            col: &col,
            weight: &weight,
        };
        let input: [f64; 18] = core::array::from_fn(|i| i as f64);
        let mut out = [0.0; 12];
        contract(rows, 0, 2, 3, 2, 3, &input, &mut out).unwrap();
        for r in 0..2 {
            for p in 0..3 {
                let at = |k: usize| input[(k * 2 + r) * 3 + p];
                assert_eq!(out[(r * 2) * 3 + p], 0.25 * at(0) + 0.75 * at(2));
                assert_eq!(out[(r * 2 + 1) * 3 + p], at(1));
            }
        }
        let bad = [0u32, 5, 1];
        let rows = SparseRows {
            ptr: &ptr,
            col: &bad,
            weight: &weight,
        };
        assert!(contract(rows, 0, 2, 3, 2, 3, &input, &mut out).is_err());
    }
}
