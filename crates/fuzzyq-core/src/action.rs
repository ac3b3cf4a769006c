//! Discrete action sets per agent and their product, the joint action set.
//!
//! Each agent `i` has `M_i` actions, each a vector of `A_i` real components (a force `(u_x, u_y)`
//! for a point mass, a wheel command for a robot). A joint action is one action per agent; its
//! **joint index** is mixed-radix with agent 0 most significant:
//! `u = ((j_0 * M_1 + j_1) * M_2 + j_2) ...`. The joint action vector concatenates the agents'
//! component vectors in agent order. "Lowest joint index" tie-breaking (see
//! [`argmax`](crate::q::argmax)) refers to this order.

use crate::error::{EvalError, check_len};
use crate::real::Real;

pub use crate::limits::MAX_AGENTS;

/// The discrete action set of one agent: `n_actions` vectors of `dim` components, stored
/// action-major in one slice.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ActionSet<'a, T> {
    values: &'a [T],
    dim: usize,
}

impl<T> Default for ActionSet<'_, T> {
    fn default() -> Self {
        Self {
            values: &[],
            dim: 1,
        }
    }
}

impl<'a, T: Real> ActionSet<'a, T> {
    /// Wraps `values` (action-major, `dim` components per action), checking that there is at
    /// least one action, the length is a multiple of `dim` and every component is finite.
    pub fn try_new(values: &'a [T], dim: usize) -> Result<Self, EvalError> {
        if dim == 0 || values.len() < dim || !values.len().is_multiple_of(dim) {
            return Err(EvalError::Length {
                what: "action set components",
                expected: dim.max(1) * (values.len() / dim.max(1)).max(1),
                found: values.len(),
            });
        }
        if let Some(index) = values.iter().position(|v| !v.is_finite()) {
            return Err(EvalError::NotFinite {
                what: "action set",
                index,
            });
        }
        Ok(Self { values, dim })
    }

    /// Number of actions `M_i`.
    #[inline]
    #[must_use]
    pub fn n_actions(&self) -> usize {
        self.values.len() / self.dim
    }

    /// Components per action `A_i`.
    #[inline]
    #[must_use]
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The components of action `j`.
    ///
    /// # Panics
    /// If `j >= n_actions()`.
    #[inline]
    #[must_use]
    pub fn action(&self, j: usize) -> &'a [T] {
        &self.values[j * self.dim..(j + 1) * self.dim]
    }

    /// All components, action-major.
    #[inline]
    #[must_use]
    pub fn values(&self) -> &'a [T] {
        self.values
    }
}

/// The joint action set `U_1 x ... x U_n` (see the [module docs](self) for the index order).
#[derive(Clone, Copy, Debug)]
pub struct JointActions<'a, T> {
    sets: [ActionSet<'a, T>; MAX_AGENTS],
    offsets: [usize; MAX_AGENTS],
    radix: [usize; MAX_AGENTS],
    /// Per agent: `u64::MAX / radix + 1` and `u64::MAX / n_actions + 1` (wrapping), the
    /// multipliers that divide and reduce 32-bit joint indices without a division.
    magic: [(u64, u64); MAX_AGENTS],
    n_agents: usize,
    n_joint: usize,
    dim: usize,
}

impl<'a, T: Real> JointActions<'a, T> {
    /// Combines the agents' action sets (between 1 and [`MAX_AGENTS`] of them).
    pub fn try_new(sets: &[ActionSet<'a, T>]) -> Result<Self, EvalError> {
        if sets.is_empty() || sets.len() > MAX_AGENTS {
            return Err(EvalError::Agents { found: sets.len() });
        }
        let mut j = Self {
            sets: [ActionSet::default(); MAX_AGENTS],
            offsets: [0; MAX_AGENTS],
            radix: [0; MAX_AGENTS],
            magic: [(0, 0); MAX_AGENTS],
            n_agents: sets.len(),
            n_joint: 1,
            dim: 0,
        };
        let mut n: u64 = 1;
        for (i, s) in sets.iter().enumerate() {
            j.sets[i] = *s;
            j.offsets[i] = j.dim;
            j.dim += s.dim();
            n = n
                .checked_mul(s.n_actions() as u64)
                .filter(|&n| n <= u64::from(u32::MAX))
                .ok_or(EvalError::OutOfRange {
                    what: "joint actions",
                    index: usize::MAX,
                    len: u32::MAX as usize,
                })?;
        }
        j.n_joint = n as usize;
        let mut stride = 1;
        for i in (0..sets.len()).rev() {
            j.radix[i] = stride;
            let magic = |d: usize| (u64::MAX / d as u64).wrapping_add(1);
            j.magic[i] = (magic(stride), magic(sets[i].n_actions()));
            stride *= sets[i].n_actions();
        }
        Ok(j)
    }

    /// Number of agents `n`.
    #[inline]
    #[must_use]
    pub fn n_agents(&self) -> usize {
        self.n_agents
    }

    /// Number of joint actions `M = M_1 * ... * M_n`.
    #[inline]
    #[must_use]
    pub fn n_joint(&self) -> usize {
        self.n_joint
    }

    /// Length of a joint action vector (the sum of the agents' component counts).
    #[inline]
    #[must_use]
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The action set of agent `i`.
    ///
    /// # Panics
    /// If `i >= n_agents()`.
    #[inline]
    #[must_use]
    pub fn agent(&self, i: usize) -> ActionSet<'a, T> {
        assert!(i < self.n_agents, "agent {i} out of range");
        self.sets[i]
    }

    /// Offset of agent `i`'s components in a joint action vector.
    #[inline]
    #[must_use]
    pub fn agent_offset(&self, i: usize) -> usize {
        self.offsets[i]
    }

    /// Agent `i`'s action index within joint action `u`.
    #[inline]
    #[must_use]
    pub fn agent_index(&self, u: usize, i: usize) -> usize {
        (u / self.radix[i]) % self.sets[i].n_actions()
    }

    /// [`Self::agent_index`] for a joint index known to be in range, without a division
    /// (multiply-high by the stored reciprocals, exact for every 32-bit index: Lemire, Kaser
    /// and Kurz, "Faster remainder by direct computation", 2019).
    #[inline]
    #[must_use]
    pub(crate) fn agent_index_in_range(&self, u: u32, i: usize) -> usize {
        let (div, rem) = self.magic[i];
        let u = u64::from(u);
        let q = if self.radix[i] == 1 {
            u
        } else {
            ((u128::from(div) * u128::from(u)) >> 64) as u64
        };
        let low = rem.wrapping_mul(q);
        ((u128::from(low) * self.sets[i].n_actions() as u128) >> 64) as usize
    }

    /// Every agent's action index within joint action `u`, for exactly `N = n_agents()`
    /// agents and `u` known to be in range: [`Self::agent_index_in_range`] for all agents at
    /// once, by successive division from the last agent (one multiply-high per agent after
    /// the first; the first agent's index is what remains).
    #[inline(always)]
    #[must_use]
    pub(crate) fn agent_indices_in_range<const N: usize>(&self, u: u32) -> [usize; N] {
        debug_assert_eq!(N, self.n_agents);
        let mut digits = [0usize; N];
        let mut r = u64::from(u);
        for i in (1..N).rev() {
            let n = self.sets[i].n_actions() as u64;
            // The reciprocal of 1 wraps to 0; one action leaves the index unchanged.
            let q = if n == 1 {
                r
            } else {
                ((u128::from(self.magic[i].1) * u128::from(r)) >> 64) as u64
            };
            digits[i] = (r - q * n) as usize;
            r = q;
        }
        if N > 0 {
            digits[0] = r as usize;
        }
        digits
    }

    /// The joint index of per-agent action indices `per_agent` (one per agent, each in range).
    pub fn compose(&self, per_agent: &[usize]) -> Result<usize, EvalError> {
        check_len("per-agent actions", self.n_agents, per_agent.len())?;
        let mut u = 0;
        for (i, &j) in per_agent.iter().enumerate() {
            let m = self.sets[i].n_actions();
            if j >= m {
                return Err(EvalError::OutOfRange {
                    what: "agent action",
                    index: j,
                    len: m,
                });
            }
            u += j * self.radix[i];
        }
        Ok(u)
    }

    /// Writes the per-agent action indices of joint action `u` into `out`.
    pub fn decompose(&self, u: usize, out: &mut [usize]) -> Result<(), EvalError> {
        check_len("per-agent actions", self.n_agents, out.len())?;
        self.check_index(u)?;
        for (i, o) in out.iter_mut().enumerate() {
            *o = self.agent_index(u, i);
        }
        Ok(())
    }

    /// Writes the joint action vector of joint action `u` into `out` (length [`dim`](Self::dim)).
    pub fn vector(&self, u: usize, out: &mut [T]) -> Result<(), EvalError> {
        check_len("joint action vector", self.dim, out.len())?;
        self.check_index(u)?;
        self.vector_unchecked(u, out);
        Ok(())
    }

    /// [`vector`](Self::vector) for an index and buffer the caller has checked.
    #[inline]
    pub fn vector_unchecked(&self, u: usize, out: &mut [T]) {
        for i in 0..self.n_agents {
            let set = self.sets[i];
            let a = set.action(self.agent_index(u, i));
            out[self.offsets[i]..self.offsets[i] + set.dim()].copy_from_slice(a);
        }
    }

    fn check_index(&self, u: usize) -> Result<(), EvalError> {
        if u < self.n_joint {
            Ok(())
        } else {
            Err(EvalError::OutOfRange {
                what: "joint action",
                index: u,
                len: self.n_joint,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agent_index_in_range_matches_division() {
        let values: std::vec::Vec<f64> = (0..2000).map(f64::from).collect();
        for sizes in [
            &[1usize][..],
            &[7],
            &[5, 5],
            &[3, 1, 4],
            &[25, 25, 25],
            &[2000, 1999, 1],
        ] {
            let sets: std::vec::Vec<ActionSet<'_, f64>> = sizes
                .iter()
                .map(|&n| ActionSet::try_new(&values[..n], 1).unwrap())
                .collect();
            let j = JointActions::try_new(&sets).unwrap();
            let step = (j.n_joint() / 50_000).max(1);
            for u in (0..j.n_joint()).step_by(step).chain([j.n_joint() - 1]) {
                let all = match j.n_agents() {
                    1 => j.agent_indices_in_range::<1>(u as u32).to_vec(),
                    2 => j.agent_indices_in_range::<2>(u as u32).to_vec(),
                    3 => j.agent_indices_in_range::<3>(u as u32).to_vec(),
                    n => unreachable!("{n} agents"),
                };
                for i in 0..j.n_agents() {
                    assert_eq!(
                        j.agent_index_in_range(u as u32, i),
                        j.agent_index(u, i),
                        "{sizes:?} u {u} agent {i}"
                    );
                    assert_eq!(all[i], j.agent_index(u, i), "{sizes:?} u {u} agent {i}");
                }
            }
        }
    }

    #[test]
    fn joint_index_is_agent_major() {
        let a = [-1.0f32, 0.0, 1.0];
        let b = [10.0f32, 20.0, 30.0, 40.0];
        let sa = ActionSet::try_new(&a, 1).unwrap();
        let sb = ActionSet::try_new(&b, 2).unwrap();
        let j = JointActions::try_new(&[sa, sb]).unwrap();
        assert_eq!(j.n_joint(), 6);
        assert_eq!(j.dim(), 3);
        assert_eq!(j.compose(&[2, 1]).unwrap(), 5);
        let mut v = [0.0; 3];
        j.vector(5, &mut v).unwrap();
        assert_eq!(v, [1.0, 30.0, 40.0]);
        let mut idx = [0; 2];
        j.decompose(3, &mut idx).unwrap();
        assert_eq!(idx, [1, 1]);
        assert!(j.vector(6, &mut v).is_err());
    }

    #[test]
    fn rejects_bad_sets() {
        assert!(ActionSet::<f32>::try_new(&[], 1).is_err());
        assert!(ActionSet::try_new(&[1.0f32, 2.0, 3.0], 2).is_err());
        assert!(ActionSet::try_new(&[1.0f32, f32::INFINITY], 1).is_err());
        assert!(JointActions::<f32>::try_new(&[]).is_err());
    }
}
