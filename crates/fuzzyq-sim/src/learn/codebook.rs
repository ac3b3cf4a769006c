//! Codebooks: the vector quantisers of VQQL (nearest centroid under a scaled distance,
//! found exactly by a k-d tree).

use fuzzyq_core::error::check_len;
use fuzzyq_core::{EvalError, MAX_DIMS};
use serde::de::{self, Deserializer};
use serde::ser::SerializeStruct;
use serde::{Deserialize, Serialize, Serializer};

use crate::error::{ConfigError, SimError, require};

/// A vector quantiser of one agent's observation: `K` centroids `c_j` in `E` dimensions and a
/// positive scale per dimension.
///
/// An observation `x` falls in the cell of its nearest centroid under the scaled squared
/// Euclidean distance `d(x, c_j) = sum_e (x_e / s_e - c_je / s_e)^2`, computed as
/// `sum_e (x_e * w_e - z_je)^2` with `w_e = 1 / s_e` and the scaled centroids
/// `z_je = c_je * w_e` (both rounded once, in that order; every lookup and [`distance`]
/// use exactly this arithmetic). Ties go to the lowest centroid index. The scale makes
/// dimensions of different ranges (positions in m, velocities in m/s) weigh comparably;
/// a scale of 1 everywhere is the plain Euclidean distance.
///
/// Lookups use a k-d tree over the scaled centroids that returns exactly the centroid a
/// brute-force scan would (same distances, same tie rule). Serialised as
/// `{ scale = [...], centroids = [[...], ...] }` (centroids in the observation's units);
/// deserialising validates.
///
/// [`distance`]: Self::distance
#[derive(Clone, Debug)]
pub struct Codebook {
    dim: usize,
    scale: Vec<f64>,
    /// Centroids in the observation's units, row-major (`K x E`).
    centroids: Vec<f64>,
    /// `1 / scale`.
    weights: Vec<f64>,
    tree: KdTree,
}

impl PartialEq for Codebook {
    fn eq(&self, other: &Self) -> bool {
        // Everything else is derived from these.
        self.dim == other.dim && self.scale == other.scale && self.centroids == other.centroids
    }
}

impl Codebook {
    /// Validates the centroids (at least one; all of the same length, 1 to [`MAX_DIMS`];
    /// finite) and the scale (one positive, finite value per dimension) and builds the
    /// lookup. Errors name the field (`codebook.centroids`, `codebook.scale`).
    pub fn new(centroids: Vec<Vec<f64>>, scale: Vec<f64>) -> Result<Self, SimError> {
        let dim = centroids.first().map_or(0, Vec::len);
        if let Some(j) = centroids.iter().position(|c| c.len() != dim) {
            return Err(ConfigError::invalid(
                "codebook.centroids",
                format!(
                    "centroid {j} has {} values, centroid 0 has {dim}",
                    centroids[j].len()
                ),
            )
            .into());
        }
        Self::from_flat(dim, centroids.concat(), scale)
    }

    /// [`new`](Self::new) with the centroids row-major in one slice (`K x dim` values).
    pub fn from_flat(dim: usize, centroids: Vec<f64>, scale: Vec<f64>) -> Result<Self, SimError> {
        let field = "codebook.centroids";
        require!(
            (1..=MAX_DIMS).contains(&dim),
            field,
            format!("centroids need 1 to {MAX_DIMS} dimensions, found {dim}"),
        );
        require!(
            !centroids.is_empty() && centroids.len().is_multiple_of(dim),
            field,
            format!(
                "needs at least one centroid of {dim} values, found {} values",
                centroids.len()
            ),
        );
        let k = centroids.len() / dim;
        if k > u32::MAX as usize {
            return Err(ConfigError::invalid(field, format!("{k} centroids are too many")).into());
        }
        require!(
            scale.len() == dim,
            "codebook.scale",
            format!(
                "needs one value per dimension ({dim}), found {}",
                scale.len()
            ),
        );
        if let Some(s) = scale.iter().find(|s| !(**s > 0.0 && s.is_finite())) {
            return Err(ConfigError::invalid(
                "codebook.scale",
                format!("must be positive finite numbers, found {s}"),
            )
            .into());
        }
        let weights: Vec<f64> = scale.iter().map(|s| 1.0 / s).collect();
        let mut scaled = centroids.clone();
        for (k, v) in scaled.iter_mut().enumerate() {
            *v *= weights[k % dim];
            require!(
                v.is_finite(),
                field,
                format!(
                    "centroid {} element {} is {} (must be finite, also after scaling)",
                    k / dim,
                    k % dim,
                    centroids[k]
                ),
            );
        }
        let tree = KdTree::build(dim, scaled);
        Ok(Self {
            dim,
            scale,
            centroids,
            weights,
            tree,
        })
    }

    /// Number of cells (centroids) `K`.
    #[must_use]
    pub fn n_cells(&self) -> usize {
        self.centroids.len() / self.dim
    }

    /// Observation length `E`.
    #[must_use]
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// The scale `s_e` of each dimension.
    #[must_use]
    pub fn scale(&self) -> &[f64] {
        &self.scale
    }

    /// The centroids in the observation's units, row-major: centroid `j` is
    /// `centroids()[j * E..(j + 1) * E]`.
    #[must_use]
    pub fn centroids(&self) -> &[f64] {
        &self.centroids
    }

    /// Centroid `j`, or `None` if there is no such cell.
    #[must_use]
    pub fn centroid(&self, j: usize) -> Option<&[f64]> {
        self.centroids.get(j * self.dim..(j + 1) * self.dim)
    }

    fn check(&self, x: &[f64]) -> Result<(), EvalError> {
        check_len("observation", self.dim, x.len())?;
        if let Some(index) = x.iter().position(|v| !v.is_finite()) {
            return Err(EvalError::NotFinite {
                what: "observation",
                index,
            });
        }
        Ok(())
    }

    /// The scaled coordinates `x_e * w_e` of an observation.
    #[inline]
    fn scaled(&self, x: &[f64]) -> [f64; MAX_DIMS] {
        let mut q = [0.0; MAX_DIMS];
        for ((q, &x), &w) in q.iter_mut().zip(x).zip(&self.weights) {
            *q = x * w;
        }
        q
    }

    /// The cell of `x` (length `E`, finite): its nearest centroid, the lowest index on ties.
    pub fn nearest(&self, x: &[f64]) -> Result<usize, SimError> {
        self.check(x)?;
        Ok(self.nearest_unchecked(x).0)
    }

    /// [`nearest`](Self::nearest) and its distance, for an observation the caller checked.
    #[inline]
    pub(crate) fn nearest_unchecked(&self, x: &[f64]) -> (usize, f64) {
        let q = self.scaled(x);
        self.tree.nearest(&q[..self.dim])
    }

    /// The nearest cell by scanning every centroid (the reference the k-d tree must match).
    #[cfg(test)]
    pub(crate) fn nearest_brute_force(&self, x: &[f64]) -> (usize, f64) {
        let q = self.scaled(x);
        self.tree.nearest_brute_force(&q[..self.dim])
    }

    /// The scaled squared distance `d(x, c_cell)` (see the [type docs](Self)).
    pub fn distance(&self, x: &[f64], cell: usize) -> Result<f64, SimError> {
        self.check(x)?;
        if cell >= self.n_cells() {
            return Err(EvalError::OutOfRange {
                what: "cell",
                index: cell,
                len: self.n_cells(),
            }
            .into());
        }
        let q = self.scaled(x);
        let t = self.tree.slot_of(cell);
        Ok(sq_dist(&q[..self.dim], self.tree.point(t)))
    }
}

/// `sum_e (a_e - b_e)^2`, summed in dimension order: the one distance of every codebook
/// lookup, so that the k-d tree and a brute-force scan agree bit for bit.
#[inline]
pub(crate) fn sq_dist(a: &[f64], b: &[f64]) -> f64 {
    let mut s = 0.0;
    for (x, y) in a.iter().zip(b) {
        let t = x - y;
        s += t * t;
    }
    s
}

/// Leaves hold at most this many centroids.
const KD_LEAF: usize = 8;

/// A k-d tree over scaled centroids for exact nearest-centroid queries.
#[derive(Clone, Debug)]
struct KdTree {
    dim: usize,
    /// Scaled centroids in tree order, row-major.
    points: Vec<f64>,
    /// Centroid index of each tree slot.
    index: Vec<usize>,
    /// Tree slot of each centroid index.
    slot: Vec<usize>,
    nodes: Vec<KdNode>,
}

/// A node: the tree slots `start..end`; an inner node splits them at `split` along
/// `split_dim` (left: coordinates `<= split`, right: `>= split`).
#[derive(Clone, Copy, Debug)]
struct KdNode {
    start: usize,
    end: usize,
    split_dim: usize,
    split: f64,
    /// Child node indices, `None` for a leaf.
    children: Option<(usize, usize)>,
}

impl KdTree {
    fn build(dim: usize, scaled: Vec<f64>) -> Self {
        let k = scaled.len() / dim;
        let mut order: Vec<usize> = (0..k).collect();
        let mut nodes = Vec::with_capacity(2 * k / KD_LEAF + 1);
        Self::build_node(&mut nodes, &mut order, 0, k, &scaled, dim);
        let mut points = Vec::with_capacity(scaled.len());
        let mut slot = vec![0; k];
        for (t, &j) in order.iter().enumerate() {
            points.extend_from_slice(&scaled[j * dim..(j + 1) * dim]);
            slot[j] = t;
        }
        Self {
            dim,
            points,
            index: order,
            slot,
            nodes,
        }
    }

    fn build_node(
        nodes: &mut Vec<KdNode>,
        order: &mut [usize],
        start: usize,
        end: usize,
        scaled: &[f64],
        dim: usize,
    ) -> usize {
        let id = nodes.len();
        nodes.push(KdNode {
            start,
            end,
            split_dim: 0,
            split: 0.0,
            children: None,
        });
        if end - start <= KD_LEAF {
            return id;
        }
        // Split the widest dimension at its median (ties ordered by index: deterministic).
        let (mut best, mut spread) = (0, 0.0);
        for e in 0..dim {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for &j in &order[start..end] {
                let v = scaled[j * dim + e];
                lo = lo.min(v);
                hi = hi.max(v);
            }
            if hi - lo > spread {
                (best, spread) = (e, hi - lo);
            }
        }
        if spread <= 0.0 {
            // All centroids of this node coincide: one leaf, scanned in full.
            return id;
        }
        let mid = start + (end - start) / 2;
        order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
            scaled[a * dim + best]
                .total_cmp(&scaled[b * dim + best])
                .then(a.cmp(&b))
        });
        let split = scaled[order[mid] * dim + best];
        let left = Self::build_node(nodes, order, start, mid, scaled, dim);
        let right = Self::build_node(nodes, order, mid, end, scaled, dim);
        nodes[id] = KdNode {
            start,
            end,
            split_dim: best,
            split,
            children: Some((left, right)),
        };
        id
    }

    #[inline]
    fn point(&self, t: usize) -> &[f64] {
        &self.points[t * self.dim..(t + 1) * self.dim]
    }

    fn slot_of(&self, cell: usize) -> usize {
        self.slot[cell]
    }

    /// The nearest centroid of the scaled query `q` and its distance (lowest index on ties).
    #[inline]
    fn nearest(&self, q: &[f64]) -> (usize, f64) {
        let mut best = (usize::MAX, f64::INFINITY);
        self.search(0, q, &mut best);
        best
    }

    fn search(&self, node: usize, q: &[f64], best: &mut (usize, f64)) {
        let n = self.nodes[node];
        match n.children {
            None => self.scan(n.start, n.end, q, best),
            Some((left, right)) => {
                let diff = q[n.split_dim] - n.split;
                let (near, far) = if diff < 0.0 {
                    (left, right)
                } else {
                    (right, left)
                };
                self.search(near, q, best);
                // Every centroid on the far side is at least |diff| away along this axis, and
                // the rounded distance is monotone in each term, so `diff^2` is a true lower
                // bound. Equal distances must be visited: a lower index may win the tie.
                if diff * diff <= best.1 {
                    self.search(far, q, best);
                }
            }
        }
    }

    #[inline]
    fn scan(&self, start: usize, end: usize, q: &[f64], best: &mut (usize, f64)) {
        for t in start..end {
            let d = sq_dist(q, self.point(t));
            let j = self.index[t];
            if d < best.1 || (d == best.1 && j < best.0) {
                *best = (j, d);
            }
        }
    }

    #[cfg(test)]
    fn nearest_brute_force(&self, q: &[f64]) -> (usize, f64) {
        let mut best = (usize::MAX, f64::INFINITY);
        for j in 0..self.index.len() {
            let d = sq_dist(q, self.point(self.slot[j]));
            if d < best.1 || best.0 == usize::MAX {
                best = (j, d);
            }
        }
        best
    }
}

/// Serialises the row-major centroids as one list per centroid.
struct Rows<'a>(&'a [f64], usize);

impl Serialize for Rows<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_seq(self.0.chunks(self.1))
    }
}

impl Serialize for Codebook {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut st = s.serialize_struct("Codebook", 2)?;
        st.serialize_field("scale", &self.scale)?;
        st.serialize_field("centroids", &Rows(&self.centroids, self.dim))?;
        st.end()
    }
}

impl<'de> Deserialize<'de> for Codebook {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        struct Data {
            scale: Vec<f64>,
            centroids: Vec<Vec<f64>>,
        }
        let data = Data::deserialize(d)?;
        Self::new(data.centroids, data.scale).map_err(de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use rand::{Rng, SeedableRng};
    use rand_pcg::Pcg64Mcg;

    use super::*;
    use crate::learn::features::FeatureSpace;

    /// A codebook of `k` pseudo-random centroids in `dim` dimensions (coordinates on a coarse
    /// lattice, so that exact ties and duplicates occur).
    fn lattice_codebook(k: usize, dim: usize, scale: Vec<f64>, seed: u64) -> Codebook {
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        let centroids: Vec<f64> = (0..k * dim)
            .map(|_| f64::from(rng.random_range(-6i32..=6)) * 0.5)
            .collect();
        Codebook::from_flat(dim, centroids, scale).unwrap()
    }

    #[test]
    fn codebook_lookup_matches_brute_force_including_ties() {
        let mut rng = Pcg64Mcg::seed_from_u64(3);
        for (k, dim, scale) in [
            (1, 1, vec![1.0]),
            (9, 2, vec![1.0, 0.5]),
            (300, 4, vec![3.0, 3.0, 0.7, 0.7]),
            (2025, 4, vec![1.0; 4]),
            (500, 7, vec![0.3; 7]),
        ] {
            let book = lattice_codebook(k, dim, scale, k as u64);
            assert_eq!(book.n_cells(), k);
            let mut queries: Vec<Vec<f64>> = (0..2000)
                .map(|_| (0..dim).map(|_| rng.random_range(-4.0..4.0)).collect())
                .collect();
            // Lattice points (many exact ties) and every centroid itself.
            queries.extend((0..500).map(|_| {
                (0..dim)
                    .map(|_| f64::from(rng.random_range(-8i32..=8)) * 0.25)
                    .collect()
            }));
            queries.extend((0..k).map(|j| book.centroid(j).unwrap().to_vec()));
            for x in &queries {
                let (j, d) = book.nearest_brute_force(x);
                let (jt, dt) = book.nearest_unchecked(x);
                assert_eq!((jt, dt.to_bits()), (j, d.to_bits()), "k {k}, x {x:?}");
                assert_eq!(book.nearest(x).unwrap(), j);
                assert_eq!(book.distance(x, j).unwrap().to_bits(), d.to_bits());
                // The lowest index among the equally near.
                for other in 0..k {
                    let e = book.distance(x, other).unwrap();
                    assert!(
                        e > d || (e == d && other >= j),
                        "k {k}, x {x:?}: {other} beats {j}"
                    );
                }
            }
        }
        // Duplicated centroids: the first copy wins, the second cell is never chosen.
        let book = Codebook::new(vec![vec![1.0], vec![0.0], vec![1.0]], vec![1.0]).unwrap();
        assert_eq!(book.nearest(&[0.9]).unwrap(), 0);
        assert_eq!(book.nearest(&[0.5]).unwrap(), 0); // tie between cells 0 and 1
        assert_eq!(book.nearest(&[0.4]).unwrap(), 1);
        // The scale weighs the dimensions: x is nearer to c1 in raw units, to c0 once the
        // second dimension is divided by 10.
        let c = vec![vec![0.0, 5.0], vec![2.0, 0.0]];
        assert_eq!(
            Codebook::new(c.clone(), vec![1.0, 1.0])
                .unwrap()
                .nearest(&[1.5, 4.0])
                .unwrap(),
            0
        );
        assert_eq!(
            Codebook::new(c, vec![1.0, 10.0])
                .unwrap()
                .nearest(&[1.5, 4.0])
                .unwrap(),
            1
        );
    }

    #[test]
    fn bad_codebooks_are_errors() {
        let err = |r: Result<Codebook, SimError>| r.expect_err("expected an error").to_string();
        assert!(err(Codebook::new(vec![], vec![])).starts_with("codebook.centroids:"));
        assert!(err(Codebook::new(vec![vec![]], vec![])).starts_with("codebook.centroids:"));
        assert!(
            err(Codebook::new(
                vec![vec![0.0, 1.0], vec![0.0]],
                vec![1.0, 1.0]
            ))
            .starts_with("codebook.centroids:")
        );
        assert!(
            err(Codebook::new(vec![vec![0.0, f64::NAN]], vec![1.0, 1.0]))
                .starts_with("codebook.centroids:")
        );
        assert!(err(Codebook::new(vec![vec![0.0]], vec![0.0])).starts_with("codebook.scale:"));
        assert!(err(Codebook::new(vec![vec![0.0]], vec![f64::NAN])).starts_with("codebook.scale:"));
        assert!(err(Codebook::new(vec![vec![0.0]], vec![1.0, 1.0])).starts_with("codebook.scale:"));
        assert!(
            err(Codebook::new(vec![vec![1e300]], vec![1e-300])).starts_with("codebook.centroids:")
        );
        assert!(
            err(Codebook::new(vec![vec![0.0; 17]], vec![1.0; 17]))
                .starts_with("codebook.centroids:")
        );
        assert!(
            err(Codebook::from_flat(2, vec![0.0; 3], vec![1.0; 2]))
                .starts_with("codebook.centroids:")
        );
        let book = Codebook::new(vec![vec![0.0, 0.0]], vec![1.0, 1.0]).unwrap();
        assert!(book.nearest(&[0.0]).is_err());
        assert!(book.nearest(&[0.0, f64::NAN]).is_err());
        assert!(book.distance(&[0.0, 0.0], 1).is_err());
        assert_eq!(book.nearest(&[f64::MAX, -f64::MAX]).unwrap(), 0);
        assert!(FeatureSpace::codebook(vec![]).is_err());
    }
}
