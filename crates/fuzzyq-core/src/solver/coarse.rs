//! The coarse start ([`SolverConfig::coarse_start`]): modified policy iteration on a grid
//! with every other core of each state variable ([`Grid::coarsened`]), its `V` interpolated
//! onto the full grid ([`Grid::interpolated_from`]) as the full run's starting `V`.
//!
//! The full run's a-posteriori bound `||V - V*|| <= gamma/(1-gamma) delta` comes from its own
//! last full backup, whatever `V` it started from, so the guarantee is the same as from
//! `V = 0`; only the number of sweeps changes. From `V = 0` the first sweeps spend their time
//! carrying the rewards across the grid, which a grid with 1/2^E of the cores per state
//! variable does at a fraction of the cost. On the Khepera robots (37.7M cores) the coarse
//! grid has 1.19M cores and costs about 0.4 s, and the full run then needs 10 full backups
//! and 42 evaluation sweeps instead of 15 and 65. On the point masses' paper grid it saves
//! nothing (that grid is already coarse), so it is off by default and on in the robots'
//! default configuration.
//!
//! The coarse grid keeps every other core counted from each variable's middle core, and both
//! ends: a symmetric grid keeps its centre, where a designer puts the finest cores. Counted
//! from the first core instead, the robots' coarse grid lost the core at 0 of every position
//! variable; the run then stopped within the same bound, but its interpolated policy lost
//! every one of 100 random starts to a collision at the goal.

use std::vec::Vec;

use super::{Grid, SolveError, par};
use crate::model::Model;
use crate::partition::Partition;
use crate::real::Real;

/// Output elements per task of an interpolation pass.
const PASS_ELEMENTS: usize = 1 << 16;

/// What the coarse start did, as a [`Solution`](super::Solution) reports it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CoarseStart {
    /// Cores of the coarse grid.
    pub cores: usize,
    /// Its sweeps (full backups and evaluation sweeps).
    pub sweeps: usize,
    /// Seconds of its solve and of the interpolation onto the full grid; where it was
    /// solved beside the run's preparation ([`solve_with`](super::solve_with)), the seconds
    /// the run waited for it beyond that preparation, and the interpolation.
    pub seconds: f64,
}

/// Every other core of `c`, counted both ways from its middle core (index `len / 2`), and
/// the first and last cores: a symmetric grid keeps its centre, where a designer puts the
/// finest cores (and the tasks here their goal). Grids of 3 cores keep all three.
fn every_other<T: Copy>(c: &[T]) -> Vec<T> {
    let (n, m) = (c.len(), c.len() / 2);
    (0..n)
        .filter(|&i| i == 0 || i + 1 == n || i % 2 == m % 2)
        .map(|i| c[i])
        .collect()
}

impl<T: Real> Grid<T> {
    /// The grid with every other core of each state variable, counted from the variable's
    /// middle core (so a symmetric grid keeps its centre), the first and last cores always
    /// kept, with the same membership functions; `None` if that drops no core (no variable
    /// has 4 cores or more).
    #[must_use]
    pub fn coarsened(&self) -> Option<Self> {
        let cores: Vec<Vec<T>> = self.cores.iter().map(|c| every_other(c)).collect();
        if cores
            .iter()
            .zip(&self.cores)
            .all(|(a, b)| a.len() == b.len())
        {
            return None;
        }
        let grid = Self::new(cores).expect("a subset of valid cores is valid");
        Some(grid.with_membership(self.membership))
    }

    /// `V` of the grid `coarse` (one value per coarse core, row-major) at every core of this
    /// grid, row-major: the fuzzy interpolation `sum_k mu_k(x) V[k]` over `coarse`'s
    /// memberships, one state variable at a time (the memberships are products over the
    /// variables, so the passes give the same sum up to rounding). A core of this grid that
    /// is also a core of `coarse` gets its value exactly.
    ///
    /// Errors: [`crate::EvalError::Length`] (through [`SolveError`]) when the grids differ
    /// in their number of state variables or `v` does not hold one value per coarse core.
    pub fn interpolated_from(&self, coarse: &Self, v: &[T]) -> Result<Vec<T>, SolveError> {
        crate::error::check_len(
            "the coarse grid's state variables",
            self.n_dims(),
            coarse.n_dims(),
        )?;
        crate::error::check_len("V", coarse.n_cores(), v.len())?;
        let mut cur = v.to_vec();
        // Shape before pass `d`: this grid's core counts before `d`, `coarse`'s from `d`.
        for d in 0..self.n_dims() {
            let part = Partition::try_from_cores(&coarse.cores[d][..])
                .expect("validated cores")
                .with_membership(coarse.membership);
            let segments: Vec<_> = self.cores[d].iter().map(|&x| part.locate(x)).collect();
            let (n_in, n_out) = (coarse.cores[d].len(), self.cores[d].len());
            let post: usize = coarse.cores[d + 1..].iter().map(Vec::len).product();
            let pre: usize = self.cores[..d].iter().map(Vec::len).product();
            let mut next = std::vec![T::ZERO; pre * n_out * post];
            let rows = (PASS_ELEMENTS / post.max(1)).max(1);
            let input = &cur[..];
            par::for_each_chunk_mut(
                &mut next,
                rows * post,
                || (),
                |_, ci, chunk| {
                    for (k, row) in chunk.chunks_mut(post).enumerate() {
                        let r = ci * rows + k;
                        let (p, i) = (r / n_out, r % n_out);
                        let s = segments[i];
                        let lo = &input[(p * n_in + s.lower) * post..][..post];
                        if s.is_split() {
                            let hi = &input[(p * n_in + s.lower + 1) * post..][..post];
                            let (wl, wu) = (s.lower_weight(), s.upper_weight);
                            for ((o, &a), &b) in row.iter_mut().zip(lo).zip(hi) {
                                *o = wl * a + wu * b;
                            }
                        } else {
                            row.copy_from_slice(lo);
                        }
                    }
                },
            );
            cur = next;
        }
        Ok(cur)
    }
}

/// Whether `model` is known only at the cores of the grid being solved (a table of a
/// Python callable's successors or rewards, block tables learned from samples or given
/// stochastic rows): a coarser grid has no model, so such runs take no coarse start.
pub(super) fn known_only_on_its_grid<T: Real, M: Model<T> + ?Sized>(model: &M) -> bool {
    model.tabulated().is_some()
        || model.reward_table().is_some()
        || (0..model.n_blocks()).any(|b| model.block_rows(b).is_some())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_other_keeps_the_middle_and_both_ends() {
        assert_eq!(every_other(&[0, 1]), [0, 1]);
        assert_eq!(every_other(&[0, 1, 2]), [0, 1, 2]);
        assert_eq!(every_other(&[0, 1, 2, 3]), [0, 2, 3]);
        assert_eq!(every_other(&[0, 1, 2, 3, 4]), [0, 2, 4]);
        assert_eq!(every_other(&[0, 1, 2, 3, 4, 5]), [0, 1, 3, 5]);
        // The robots' position cores: 0 stays.
        let robots = [
            -6.0, -4.0, -2.5, -1.5, -0.8, -0.4, -0.2, -0.1, -0.05, 0.0, 0.05, 0.1, 0.2, 0.4, 0.8,
            1.5, 2.5, 4.0, 6.0,
        ];
        assert_eq!(
            every_other(&robots),
            [-6.0, -4.0, -1.5, -0.4, -0.1, 0.0, 0.1, 0.4, 1.5, 4.0, 6.0]
        );
    }

    /// The passes give the product memberships' interpolation at every core (within
    /// rounding), and the coarse cores' own values exactly; crisp grids take the nearest
    /// coarse core's value.
    #[test]
    fn interpolation_matches_the_memberships() {
        use crate::partition::Membership;
        let fine = Grid::new(std::vec![
            std::vec![-2.0f64, -1.0, -0.25, 0.0, 0.5, 3.0],
            std::vec![0.0, 1.0, 2.0],
            std::vec![-1.0, 0.0, 0.3, 1.0, 2.0],
        ])
        .unwrap();
        for membership in [Membership::Triangular, Membership::Crisp] {
            let fine = fine.clone().with_membership(membership);
            let coarse = fine.coarsened().unwrap();
            assert_eq!(coarse.cores()[0], [-2.0, -1.0, 0.0, 3.0]);
            assert_eq!(coarse.cores()[1], [0.0, 1.0, 2.0]);
            assert_eq!(coarse.cores()[2], [-1.0, 0.3, 2.0]);
            let v: Vec<f64> = (0..coarse.n_cores())
                .map(|i| ((i * 37) % 11) as f64 - 4.5)
                .collect();
            let out = fine.interpolated_from(&coarse, &v).unwrap();
            let (fv, cv) = (fine.view(), coarse.view());
            let mut x = [0.0; 3];
            for (g, &o) in out.iter().enumerate() {
                fv.core_state(g, &mut x).unwrap();
                let want = cv.active(&x).unwrap().interpolate(&v);
                assert!(
                    (o - want).abs() <= 1e-12,
                    "{membership:?} core {g}: {o} vs {want}"
                );
                let on_coarse = (0..3).all(|d| coarse.cores()[d].contains(&x[d]));
                if on_coarse {
                    assert_eq!(o.to_bits(), want.to_bits(), "core {g}");
                }
            }
        }
        assert!(
            Grid::new(std::vec![std::vec![0.0f64, 1.0, 2.0]; 2])
                .unwrap()
                .coarsened()
                .is_none()
        );
        let other = Grid::new(std::vec![std::vec![0.0f64, 1.0]]).unwrap();
        assert!(fine.interpolated_from(&other, &[0.0, 1.0]).is_err());
        let coarse = fine.coarsened().unwrap();
        assert!(fine.interpolated_from(&coarse, &[0.0]).is_err());
    }
}
