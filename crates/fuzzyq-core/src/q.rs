//! Q evaluation and the policies of the `joint` layout.
//!
//! # `joint` layout (eqs 7, 8, 20)
//! `theta[d, u]` over joint cores `d` and joint actions `u`, stored row-major
//! (`theta[d * M + u]`). `Q(x, u) = sum_d mu_d(x) theta[d, u]`. For problems too large to store
//! `theta` (the paper's has 2.56e9 entries) the solver keeps only `V[d] = max_u theta[d, u]`;
//! [`crate::backup::q_values_from_v`] evaluates `Q(x, .)` from `V` and the model.
//!
//! The `additive` layout (eqs 12-13 read per agent) and its sample updates are in
//! [`crate::additive`].
//!
//! # Policies
//! - greedy (eq 7): the joint action maximising `Q(x, .)`, ties broken towards the lowest
//!   joint index ([`argmax`]). Every agent applies the same rule to the same values, which is
//!   the implicit coordination of the paper's section 2.2.
//! - interpolated (eq 22): `h(x) = sum_d mu_d(x) u(j*_d)` with `j*_d` the greedy joint action of
//!   core `d`: a continuous joint action vector, the membership-weighted average of the cores'
//!   greedy actions. It needs only a per-core action table, so a controller can run it in
//!   microseconds.

use crate::action::JointActions;
use crate::error::{EvalError, check_len};
use crate::partition::ProductPartition;
use crate::real::Real;

crate::named_option! {
    /// Which policy acts on a solution (see the [module docs](self)).
    #[derive(Default)]
    pub enum PolicyKind: "policy" {
        /// The joint action maximising `Q(x, .)`, lowest index on ties (eq 7).
        #[default]
        Greedy = "greedy" => "the joint action maximising Q(x, .), lowest index on ties (eq 7)",
        /// The membership-weighted average of the active cores' greedy actions (eq 22).
        Interpolated = "interpolated" => "the membership-weighted average of the active cores' greedy actions (eq 22)",
    }
}

/// Index of the largest value, the lowest index among ties; NaNs never win. `None` if `q` is
/// empty or all NaN.
#[inline]
#[must_use]
pub fn argmax<T: Real>(q: &[T]) -> Option<usize> {
    let mut best: Option<(usize, T)> = None;
    for (i, &v) in q.iter().enumerate() {
        if v.is_nan() {
            continue;
        }
        match best {
            Some((_, b)) if v <= b => {}
            _ => best = Some((i, v)),
        }
    }
    best.map(|(i, _)| i)
}

/// `out[u] = Q(x, u) = sum_d mu_d(x) theta[d, u]` for the `joint` layout with stored `theta`
/// (`theta.len() == N * M`, `out.len() == M`).
pub fn q_values<T: Real>(
    grid: &ProductPartition<'_, T>,
    theta: &[T],
    x: &[T],
    out: &mut [T],
) -> Result<(), EvalError> {
    let m = out.len();
    check_len("theta", grid.n_cores() * m, theta.len())?;
    let active = grid.active(x)?;
    out.fill(T::ZERO);
    active.for_each(|d, w| {
        let row = &theta[d * m..(d + 1) * m];
        for (o, &t) in out.iter_mut().zip(row) {
            *o += w * t;
        }
    });
    Ok(())
}

/// The greedy joint action at `x` for stored `theta` (eq 7), using `q` (length `M`) as scratch.
pub fn greedy_action<T: Real>(
    grid: &ProductPartition<'_, T>,
    theta: &[T],
    x: &[T],
    q: &mut [T],
) -> Result<usize, EvalError> {
    q_values(grid, theta, x, q)?;
    argmax(q).ok_or(EvalError::Length {
        what: "Q-values",
        expected: 1,
        found: 0,
    })
}

/// The interpolated policy of eq 22: `out = sum_d mu_d(x) u(greedy[d])`, where `greedy[d]` is
/// the greedy joint action index of core `d` and `u(.)` its joint action vector
/// (`out.len() == joint.dim()`).
///
/// Each component is then clamped into the range of that component over its agent's actions:
/// the memberships sum to 1 only up to rounding, so the weighted average of actions at a bound
/// could otherwise leave it (for example `2.0000014` for levels in `[-2, 2]` in `f32`).
pub fn interpolated_action<T: Real>(
    grid: &ProductPartition<'_, T>,
    joint: &JointActions<'_, T>,
    greedy: &[u32],
    x: &[T],
    out: &mut [T],
) -> Result<(), EvalError> {
    interpolated_action_in(grid, joint, greedy, x, out)
}

/// A per-core table of greedy joint actions in the smallest unsigned integer type that holds
/// them (`u8`, `u16` or `u32`): what [`interpolated_action_in`] reads.
pub trait GreedyTable {
    /// Entries (one per core).
    fn len(&self) -> usize;
    /// Whether the table is empty.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// The greedy joint action of core `core` (`core < len()`).
    fn action(&self, core: usize) -> u32;
    /// `out[k] = action(cores[k])` for every `k` (`out.len() >= cores.len()`), returning the
    /// largest (0 for no cores). One pass with nothing else in flight, so that the loads'
    /// cache misses overlap.
    fn gather(&self, cores: &[usize], out: &mut [u32]) -> u32 {
        let mut top = 0;
        for (a, &d) in out.iter_mut().zip(cores) {
            *a = self.action(d);
            top = top.max(*a);
        }
        top
    }
}

macro_rules! greedy_table {
    ($($t:ty),*) => {$(
        impl GreedyTable for [$t] {
            #[inline]
            fn len(&self) -> usize {
                <[$t]>::len(self)
            }
            #[inline]
            fn action(&self, core: usize) -> u32 {
                u32::from(self[core])
            }
        }
    )*};
}
greedy_table!(u8, u16, u32);

/// [`interpolated_action`] on a greedy table of any width ([`GreedyTable`]): the same sums in
/// the same order, so the same bits for the same actions.
pub fn interpolated_action_in<T: Real, G: GreedyTable + ?Sized>(
    grid: &ProductPartition<'_, T>,
    joint: &JointActions<'_, T>,
    greedy: &G,
    x: &[T],
    out: &mut [T],
) -> Result<(), EvalError> {
    check_len("greedy actions", grid.n_cores(), greedy.len())?;
    check_len("joint action vector", joint.dim(), out.len())?;
    let active = grid.active(x)?;
    // Up to `FAST` active cores (8 split variables) are listed on the stack first, so that
    // their greedy actions load together; the order and the sums are those of `for_each`.
    const FAST: usize = 256;
    let mut index = [0usize; FAST];
    let mut weight = [T::ZERO; FAST];
    if let Some(n) = active.write_to(&mut index, &mut weight) {
        let weight = &weight[..n];
        // The greedy actions are loaded in a pass of their own: with nothing else in flight,
        // all their cache misses overlap (loading them inside the sums measured 30% slower).
        let mut action = [0u32; FAST];
        let top = greedy.gather(&index[..n], &mut action);
        if top as usize >= joint.n_joint() {
            return Err(greedy_out_of_range(joint, top));
        }
        let action = &action[..n];
        if !sum_actions_in_registers(joint, action, weight, out) {
            out.fill(T::ZERO);
            // Agent by agent, the components summed in registers (in core order, as below).
            for i in 0..joint.n_agents() {
                let set = joint.agent(i);
                let o = &mut out[joint.agent_offset(i)..][..set.dim()];
                if set.dim() <= 4 {
                    let mut acc = [T::ZERO; 4];
                    for (&u, &w) in action.iter().zip(weight) {
                        let a = set.action(joint.agent_index_in_range(u, i));
                        for (y, &c) in acc.iter_mut().zip(a) {
                            *y += w * c;
                        }
                    }
                    o.copy_from_slice(&acc[..o.len()]);
                } else {
                    for (&u, &w) in action.iter().zip(weight) {
                        let a = set.action(joint.agent_index_in_range(u, i));
                        for (y, &c) in o.iter_mut().zip(a) {
                            *y += w * c;
                        }
                    }
                }
            }
        }
    } else {
        // Validate before accumulating so the callback cannot fail halfway.
        let mut bad = None;
        active.for_each(|d, _| {
            if greedy.action(d) as usize >= joint.n_joint() {
                bad = Some(greedy.action(d));
            }
        });
        if let Some(u) = bad {
            return Err(greedy_out_of_range(joint, u));
        }
        out.fill(T::ZERO);
        active.for_each(|d, w| add_action(joint, greedy.action(d) as usize, w, out));
    }
    for i in 0..joint.n_agents() {
        let set = joint.agent(i);
        let o = &mut out[joint.agent_offset(i)..][..set.dim()];
        match set.dim() {
            1 => clamp_into_actions::<T, 1>(set.values(), o),
            2 => clamp_into_actions::<T, 2>(set.values(), o),
            _ => {
                for (k, o) in o.iter_mut().enumerate() {
                    let (mut lo, mut hi) = (set.action(0)[k], set.action(0)[k]);
                    for j in 1..set.n_actions() {
                        let c = set.action(j)[k];
                        lo = if c < lo { c } else { lo };
                        hi = if c > hi { c } else { hi };
                    }
                    clamp(o, lo, hi);
                }
            }
        }
    }
    Ok(())
}

/// Clamps each of the `D` components `out` into that component's range over the actions
/// `values` (action-major, `D` components each), in one pass over the actions.
#[inline(always)]
fn clamp_into_actions<T: Real, const D: usize>(values: &[T], out: &mut [T]) {
    let (rows, _) = values.as_chunks::<D>();
    let Some((first, rest)) = rows.split_first() else {
        return;
    };
    for (k, o) in out.iter_mut().enumerate().take(D) {
        // Component by component: two independent scalar chains each (the values are
        // finite, so comparisons need no NaN handling).
        let (mut lo, mut hi) = (first[k], first[k]);
        for a in rest {
            lo = if a[k] < lo { a[k] } else { lo };
            hi = if a[k] > hi { a[k] } else { hi };
        }
        clamp(o, lo, hi);
    }
}

/// `o` clamped into `[lo, hi]` (left alone if NaN).
#[inline(always)]
fn clamp<T: Real>(o: &mut T, lo: T, hi: T) {
    if *o > hi {
        *o = hi;
    } else if *o < lo {
        *o = lo;
    }
}

/// The error for a greedy table entry `u` that names no joint action.
#[cold]
fn greedy_out_of_range<T: Real>(joint: &JointActions<'_, T>, u: u32) -> EvalError {
    EvalError::OutOfRange {
        what: "greedy action",
        index: u as usize,
        len: joint.n_joint(),
    }
}

/// `out = sum_k weight[k] * (the vector of joint action action[k])`, every component's sum in
/// core order (the bits of the agent-by-agent loop), in one pass with all components in
/// registers so that their addition chains overlap.
///
/// Returns `false` (and leaves `out` alone) unless the joint action has 1 to 4 agents of 1 or
/// 2 components each, the shapes it is instantiated for. Every `action[k]` must name a joint
/// action.
#[inline]
fn sum_actions_in_registers<T: Real>(
    joint: &JointActions<'_, T>,
    action: &[u32],
    weight: &[T],
    out: &mut [T],
) -> bool {
    let d = joint.agent(0).dim();
    if (1..joint.n_agents()).any(|i| joint.agent(i).dim() != d) {
        return false;
    }
    match (joint.n_agents(), d) {
        (1, 1) => sum_uniform::<T, 1, 1>(joint, action, weight, out),
        (1, 2) => sum_uniform::<T, 1, 2>(joint, action, weight, out),
        (2, 1) => sum_uniform::<T, 2, 1>(joint, action, weight, out),
        (2, 2) => sum_uniform::<T, 2, 2>(joint, action, weight, out),
        (3, 1) => sum_uniform::<T, 3, 1>(joint, action, weight, out),
        (3, 2) => sum_uniform::<T, 3, 2>(joint, action, weight, out),
        (4, 1) => sum_uniform::<T, 4, 1>(joint, action, weight, out),
        (4, 2) => sum_uniform::<T, 4, 2>(joint, action, weight, out),
        _ => return false,
    }
    true
}

/// [`sum_actions_in_registers`] for `N` agents of `D` components each.
#[inline(always)]
fn sum_uniform<T: Real, const N: usize, const D: usize>(
    joint: &JointActions<'_, T>,
    action: &[u32],
    weight: &[T],
    out: &mut [T],
) {
    // Each agent's actions as `[T; D]` rows: one bounds check per agent and core.
    let mut values: [&[[T; D]]; N] = [&[]; N];
    for (i, v) in values.iter_mut().enumerate() {
        *v = joint.agent(i).values().as_chunks::<D>().0;
    }
    let mut acc = [[T::ZERO; D]; N];
    for (&u, &w) in action.iter().zip(weight) {
        let digits = joint.agent_indices_in_range::<N>(u);
        for ((sum, vals), &j) in acc.iter_mut().zip(&values).zip(&digits) {
            for (y, &c) in sum.iter_mut().zip(&vals[j]) {
                *y += w * c;
            }
        }
    }
    for (o, c) in out.chunks_exact_mut(D).zip(&acc) {
        o.copy_from_slice(c);
    }
}

/// `out += w * (joint action u's vector)`, agent by agent.
#[inline(always)]
fn add_action<T: Real>(joint: &JointActions<'_, T>, u: usize, w: T, out: &mut [T]) {
    for i in 0..joint.n_agents() {
        let set = joint.agent(i);
        let a = set.action(joint.agent_index(u, i));
        let off = joint.agent_offset(i);
        for (o, &c) in out[off..off + set.dim()].iter_mut().zip(a) {
            *o += w * c;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::action::ActionSet;

    #[test]
    fn argmax_prefers_lowest_index_and_skips_nan() {
        assert_eq!(argmax(&[1.0f32, 3.0, 3.0, 2.0]), Some(1));
        assert_eq!(argmax(&[f32::NAN, 0.5, 0.5]), Some(1));
        assert_eq!(argmax::<f64>(&[]), None);
        assert_eq!(argmax(&[f64::NAN]), None);
        assert_eq!(argmax(&[f64::NEG_INFINITY, -1.0]), Some(1));
    }

    #[test]
    fn joint_q_interpolates_theta() {
        let c = [0.0f64, 1.0];
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let theta = [1.0, 0.0, 0.0, 3.0]; // core 0: (1, 0), core 1: (0, 3)
        let mut q = [0.0; 2];
        q_values(&g, &theta, &[0.25], &mut q).unwrap();
        assert_eq!(q, [0.75, 0.75]);
        assert_eq!(greedy_action(&g, &theta, &[0.25], &mut q).unwrap(), 0);
        assert_eq!(greedy_action(&g, &theta, &[0.3], &mut q).unwrap(), 1);
    }

    #[test]
    fn interpolated_policy_averages_core_actions() {
        let c = [0.0f64, 1.0];
        let g = ProductPartition::try_new(&[&c[..]]).unwrap();
        let a = [-2.0, 0.0, 2.0];
        let set = ActionSet::try_new(&a, 1).unwrap();
        let j = JointActions::try_new(&[set]).unwrap();
        let mut out = [0.0];
        interpolated_action(&g, &j, &[0, 2], &[0.25], &mut out).unwrap();
        assert!((out[0] - (0.75 * -2.0 + 0.25 * 2.0)).abs() < 1e-12);
        out[0] = 7.0;
        assert_eq!(
            interpolated_action(&g, &j, &[0, 3], &[0.25], &mut out),
            Err(EvalError::OutOfRange {
                what: "greedy action",
                index: 3,
                len: 3
            })
        );
        assert_eq!(
            out[0], 7.0,
            "a refused greedy table leaves the output alone"
        );
    }

    /// The stack fast path (up to 8 split variables) and the callback path (more) give the
    /// bits of the plain definition: `sum_d mu_d a(u_d)` in `for_each` order, clamped.
    #[test]
    fn interpolated_action_matches_the_definition_bit_for_bit() {
        let cores = [-1.0f32, -0.3, 0.2, 1.0];
        let acts = [-2.0f32, -0.7, 0.0, 0.9, 2.0, 1.3, -1.1, 0.4];
        // Per agent (components, actions): the mixed and wide shapes take the agent-by-agent
        // loop, the uniform ones (1 to 4 agents of 1 or 2 components) the one-pass sums.
        let shapes: [&[(usize, usize)]; 12] = [
            &[(2, 3), (1, 5)],
            &[(3, 2), (3, 2)],
            &[(1, 5)],
            &[(2, 4)],
            &[(1, 5), (1, 1)],
            &[(2, 3), (2, 4)],
            &[(1, 2), (1, 7), (1, 3)],
            &[(2, 2), (2, 3), (2, 1)],
            &[(1, 3), (1, 2), (1, 4), (1, 2)],
            &[(2, 2), (2, 2), (2, 3), (2, 2)],
            &[(1, 2), (1, 2), (1, 2), (1, 2), (1, 2)],
            &[(5, 1), (1, 3)],
        ];
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = move || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            s
        };
        let mut values = std::vec::Vec::new();
        for (k, shape) in shapes.iter().enumerate() {
            values.clear();
            for &(dim, n) in *shape {
                values.push(
                    (0..dim * n)
                        .map(|c| acts[(c * 3 + k) % acts.len()])
                        .collect::<std::vec::Vec<_>>(),
                );
            }
            let sets: std::vec::Vec<_> = shape
                .iter()
                .zip(&values)
                .map(|(&(dim, _), v)| ActionSet::try_new(v, dim).unwrap())
                .collect();
            let j = JointActions::try_new(&sets).unwrap();
            for dims in [1usize, 4, 8, 9] {
                let parts = std::vec![&cores[..]; dims];
                let g = ProductPartition::try_new(&parts).unwrap();
                let greedy: std::vec::Vec<u32> = (0..g.n_cores())
                    .map(|_| (next() % j.n_joint() as u64) as u32)
                    .collect();
                for _ in 0..20 {
                    let x: std::vec::Vec<f32> = (0..dims)
                        .map(|_| -1.0 + 2.0 * (next() >> 40) as f32 / (1u64 << 24) as f32)
                        .collect();
                    let mut fast = std::vec![0.0f32; j.dim()];
                    interpolated_action(&g, &j, &greedy, &x, &mut fast).unwrap();
                    let mut want = std::vec![0.0f32; j.dim()];
                    let mut v = std::vec![0.0f32; j.dim()];
                    g.active(&x).unwrap().for_each(|d, w| {
                        j.vector(greedy[d] as usize, &mut v).unwrap();
                        for (o, c) in want.iter_mut().zip(&v) {
                            *o += w * c;
                        }
                    });
                    for i in 0..j.n_agents() {
                        let set = j.agent(i);
                        for c in 0..set.dim() {
                            let comp = (0..set.n_actions()).map(|a| set.action(a)[c]);
                            let lo = comp.clone().fold(f32::INFINITY, f32::min);
                            let hi = comp.fold(f32::NEG_INFINITY, f32::max);
                            let o = &mut want[j.agent_offset(i) + c];
                            *o = o.clamp(lo, hi);
                        }
                    }
                    let bits =
                        |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<std::vec::Vec<_>>();
                    assert_eq!(bits(&fast), bits(&want), "{shape:?}, {dims} dims at {x:?}");
                }
            }
        }
    }
}
