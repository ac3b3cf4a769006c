//! VQQL, the crisp baseline of the paper's Table 1 (section 4; the CMOMMT learner of Fernandez
//! and Parker, after Fernandez and Borrajo 1999): a vector quantiser of each agent's own state,
//! built by the Generalized Lloyd algorithm (k-means), then tabular Q-learning over its cells.
//!
//! # The quantiser ([`build_codebook`])
//! 1. Exploration ([`explore`]): episodes of [`explore_steps`](VqqlConfig::explore_steps)
//!    uniformly random actions (every agent independently, every action alike) from the
//!    [`Starts`] on a [`PointMassEnv`]; every visited state `x_0, ..., x_K` of an episode is
//!    recorded until [`samples`](VqqlConfig::samples) states are collected. Agent `i`'s samples
//!    are its own `(s_x, s_y, v_x, v_y)`.
//! 2. Metric: the samples are standardised, each dimension divided by its standard deviation
//!    over the samples (a dimension that does not vary keeps scale 1). Positions range over
//!    `[-6, 6]` m and velocities over `[-3, 3]` m/s, and random forces keep most velocities
//!    well inside that range: on raw coordinates nearly all cells would split positions. The
//!    scale is stored in the [`Codebook`], so lookups use the metric the cells were built in.
//! 3. Seeding: k-means++ (Arthur and Vassilvitskii 2007): the first centroid is a uniformly
//!    drawn sample, each next one a sample drawn with probability proportional to its squared
//!    distance to the nearest centroid so far. Centroids are distinct samples; fewer distinct
//!    samples than cells is an error.
//! 4. Lloyd iterations ([`generalized_lloyd`]): assign every sample to its nearest centroid
//!    (lowest index on ties, the codebook's exact lookup), then move every centroid to the mean
//!    of its samples (summed in sample order). A centroid that no sample chose is re-seeded at
//!    the sample farthest from its own (updated) centroid, the lowest sample index on ties, and
//!    later empty cells at the farthest sample from every centroid placed so far. The
//!    distortion (mean squared scaled distance to the nearest centroid) never increases. The
//!    iterations stop when its relative decrease is at most
//!    [`lloyd_tolerance`](VqqlConfig::lloyd_tolerance), or after
//!    [`lloyd_iterations`](VqqlConfig::lloyd_iterations) assignments, but only with every cell
//!    non-empty under the last assignment (a few repair iterations are allowed past the limit).
//!
//! Everything draws from one [`Pcg64Mcg`] seeded with [`seed`](VqqlConfig::seed) (exploration,
//! then agent 0's seeding, agent 1's, ...) and runs on one thread: the codebooks are
//! bit-identical for a seed.
//!
//! # Learning ([`train_vqql`])
//! [`crate::learn::fql::learn`] on [`FeatureSpace::codebook`] features: an observation activates the one cell
//! of its nearest centroid with membership 1, so the corrected update
//! `phi[i][j * M + u_i] += alpha * delta` is exactly tabular Q-learning on the cells (with the
//! additive, decentralised joint value of `docs/design.md`, section 2, as for fuzzy
//! Q-learning). The literal update is available too, as for fuzzy features.
//!
//! # Parameter count
//! The default [`cells`](VqqlConfig::cells) is 2025, the number of own-state cores of the
//! paper's fuzzy grid (`9 * 9 * 5 * 5`), so that the table has exactly as many parameters as
//! the additive fuzzy layout: 2 agents x 2025 cells x 25 actions = 101,250.

use fuzzyq_core::MAX_DIMS;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError, require};
use crate::learn::codebook::{Codebook, sq_dist};
use crate::learn::fql::{Environment, FeatureSpace, FqlConfig, FqlOutcome};
use crate::learn::tasks::pointmass::{PointMassEnv, train_fql};
use crate::model::pointmass::{PointMass, Starts};

/// Lloyd iterations allowed past [`VqqlConfig::lloyd_iterations`] to fill empty cells.
pub const MAX_REPAIR_ITERATIONS: usize = 100;

/// Settings of the vector quantiser. Missing fields take their [`Default`] values when
/// deserialised; unknown fields are rejected.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VqqlConfig {
    /// Cells (centroids) per agent, `>= 1`.
    pub cells: usize,
    /// Explored states used for k-means, per agent; at least `cells`.
    pub samples: usize,
    /// Random-action steps per exploration episode, `>= 1`.
    pub explore_steps: usize,
    /// Largest number of Lloyd assignments, `>= 1`.
    pub lloyd_iterations: usize,
    /// Stop when the distortion's relative decrease is at most this, finite and `>= 0`.
    pub lloyd_tolerance: f64,
    /// Seed of the exploration and of the k-means++ seeding.
    pub seed: u64,
}

impl Default for VqqlConfig {
    /// 2025 cells (the own-state cores of the paper's fuzzy grid, see the
    /// [module docs](self)), 40,000 samples from episodes of 150 steps (the learning episode
    /// length of [`crate::learn::tasks::pointmass::default_fql_config`]), at most 25 Lloyd iterations,
    /// tolerance `1e-4`, seed 0.
    fn default() -> Self {
        Self {
            cells: 2025,
            samples: 40_000,
            explore_steps: 150,
            lloyd_iterations: 25,
            lloyd_tolerance: 1e-4,
            seed: 0,
        }
    }
}

impl VqqlConfig {
    /// Checks every field; the error names the first invalid one (`vqql.<field>`).
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bad = |field: &str, reason: String| {
            Err(ConfigError::invalid(format!("vqql.{field}"), reason))
        };
        if self.cells == 0 {
            return bad("cells", "must be at least 1".into());
        }
        if self.cells > u32::MAX as usize {
            return bad("cells", format!("must be at most {}", u32::MAX));
        }
        if self.samples < self.cells {
            return bad(
                "samples",
                format!(
                    "must be at least cells = {}, got {}",
                    self.cells, self.samples
                ),
            );
        }
        if self.explore_steps == 0 {
            return bad("explore_steps", "must be at least 1".into());
        }
        if self.lloyd_iterations == 0 {
            return bad("lloyd_iterations", "must be at least 1".into());
        }
        if !(self.lloyd_tolerance >= 0.0 && self.lloyd_tolerance.is_finite()) {
            return bad(
                "lloyd_tolerance",
                format!("must be a finite number >= 0, got {}", self.lloyd_tolerance),
            );
        }
        Ok(())
    }
}

/// What the Generalized Lloyd algorithm did for one agent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct QuantiserReport {
    /// Samples quantised.
    pub samples: usize,
    /// Cells.
    pub cells: usize,
    /// Assignments run (each after the first preceded by a centroid update).
    pub iterations: usize,
    /// The relative-decrease test passed (otherwise the iteration limit stopped the run).
    pub converged: bool,
    /// The distortion of the final codebook: the mean over the samples of the squared scaled
    /// distance to their nearest centroid.
    pub distortion: f64,
    /// The distortion after every assignment, oldest first (non-increasing).
    pub distortion_history: Vec<f64>,
    /// Empty cells re-seeded over the run.
    pub reseeded: usize,
    /// Samples in the smallest and the largest cell under the final assignment (the smallest
    /// is at least 1).
    pub cell_sizes: [usize; 2],
}

/// What [`build_codebook`] did: a summary over the agents and one [`QuantiserReport`] per
/// agent.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LloydReport {
    /// The largest number of Lloyd assignments over the agents.
    pub iterations: usize,
    /// The mean over the agents of their final distortions.
    pub distortion: f64,
    /// Values the codebooks store: every centroid coordinate and every scale, all agents.
    pub codebook_values: usize,
    /// Per agent.
    pub agents: Vec<QuantiserReport>,
}

impl LloydReport {
    fn new(agents: Vec<QuantiserReport>, features: &FeatureSpace) -> Self {
        Self {
            iterations: agents.iter().map(|a| a.iterations).max().unwrap_or(0),
            distortion: agents.iter().map(|a| a.distortion).sum::<f64>()
                / agents.len().max(1) as f64,
            codebook_values: features
                .codebooks()
                .iter()
                .map(|b| b.centroids().len() + b.scale().len())
                .sum(),
            agents,
        }
    }
}

/// Explores the point-mass task with uniformly random actions from `starts` (see the
/// [module docs](self)): `samples` states per agent, row-major `(s_x, s_y, v_x, v_y)`, from
/// episodes of `steps` steps, drawing from `rng`.
pub fn explore(
    model: &PointMass,
    starts: &Starts,
    samples: usize,
    steps: usize,
    rng: &mut Pcg64Mcg,
) -> Result<Vec<Vec<f64>>, SimError> {
    let mut env = PointMassEnv::new(model, starts.clone())?;
    let out = explore_env(&mut env, samples, steps, rng)?;
    if let Some(e) = env.take_error() {
        return Err(e);
    }
    Ok(out)
}

/// Explores any environment with uniformly random actions (every agent independently, every
/// action alike): `samples` observations per agent, row-major, from episodes of at most
/// `steps` steps (an episode also ends at a terminal transition or when the environment cuts
/// it), each episode's first observation included, drawing from `rng`.
pub fn explore_env<E: Environment>(
    env: &mut E,
    samples: usize,
    steps: usize,
    rng: &mut Pcg64Mcg,
) -> Result<Vec<Vec<f64>>, SimError> {
    if steps == 0 {
        return Err(ConfigError::invalid("vqql.explore_steps", "must be at least 1").into());
    }
    let agents = env.n_agents();
    let m: Vec<usize> = (0..agents).map(|i| env.n_actions(i)).collect();
    let dims: Vec<usize> = (0..agents).map(|i| env.obs_dim(i)).collect();
    let mut out = Vec::with_capacity(agents);
    for &d in &dims {
        let mut v = Vec::new();
        v.try_reserve_exact(samples.saturating_mul(d))
            .map_err(|_| {
                ConfigError::invalid(
                    "vqql.samples",
                    format!("{samples} samples do not fit in memory"),
                )
            })?;
        out.push(v);
    }
    let mut actions = vec![0; agents];
    let mut collected = 0;
    let record = |env: &E, out: &mut [Vec<f64>]| {
        for (i, o) in out.iter_mut().enumerate() {
            let at = o.len();
            o.resize(at + dims[i], 0.0);
            env.observe(i, &mut o[at..]);
        }
    };
    while collected < samples {
        env.reset(rng);
        record(env, &mut out);
        collected += 1;
        for _ in 0..steps {
            if collected == samples {
                break;
            }
            for (a, &mi) in actions.iter_mut().zip(&m) {
                *a = rng.random_range(0..mi);
            }
            let ended = env.step(&actions, rng).terminal;
            record(env, &mut out);
            collected += 1;
            if ended || env.truncated() {
                break;
            }
        }
    }
    Ok(out)
}

/// Per-dimension standard deviation of row-major samples (1 where it is 0 or not finite).
fn standard_scale(samples: &[f64], dim: usize) -> Vec<f64> {
    let n = (samples.len() / dim) as f64;
    (0..dim)
        .map(|e| {
            let mean = samples.iter().skip(e).step_by(dim).sum::<f64>() / n;
            let var = samples
                .iter()
                .skip(e)
                .step_by(dim)
                .map(|v| (v - mean) * (v - mean))
                .sum::<f64>()
                / n;
            let sd = var.sqrt();
            if sd > 1e-9 && sd.is_finite() { sd } else { 1.0 }
        })
        .collect()
}

/// k-means++ seeding on scaled samples: the indices of `cells` distinct samples.
fn seed_plus_plus(
    scaled: &[f64],
    dim: usize,
    cells: usize,
    rng: &mut Pcg64Mcg,
) -> Result<Vec<usize>, SimError> {
    let n = scaled.len() / dim;
    let row = |i: usize| &scaled[i * dim..(i + 1) * dim];
    let first = rng.random_range(0..n);
    let mut chosen = Vec::with_capacity(cells);
    chosen.push(first);
    let mut dmin: Vec<f64> = (0..n).map(|i| sq_dist(row(i), row(first))).collect();
    while chosen.len() < cells {
        let total: f64 = dmin.iter().sum();
        require!(
            total > 0.0,
            "vqql.samples",
            format!(
                "the samples hold only {} distinct states, fewer than cells = {cells}",
                chosen.len()
            ),
        );
        let r = rng.random::<f64>() * total;
        let mut acc = 0.0;
        let mut pick = None;
        for (i, &d) in dmin.iter().enumerate() {
            if d > 0.0 {
                acc += d;
                pick = Some(i);
                if acc > r {
                    break;
                }
            }
        }
        // `pick` is the last positive sample if rounding kept `acc <= r` (and always some
        // sample, since `total > 0`).
        let Some(pick) = pick else {
            return Err(
                ConfigError::invalid("vqql.samples", "no sample to seed a cell from").into(),
            );
        };
        chosen.push(pick);
        let p = row(pick).to_vec();
        for (i, d) in dmin.iter_mut().enumerate() {
            let e = sq_dist(&scaled[i * dim..(i + 1) * dim], &p);
            if e < *d {
                *d = e;
            }
        }
    }
    Ok(chosen)
}

/// The Generalized Lloyd algorithm (see the [module docs](self)) on `samples`, row-major
/// vectors of `dim` values: a codebook of `cells` centroids in the samples' standardised
/// metric, seeded by k-means++ from `seed`. Errors (never panics): `dim` not in
/// `1..=16`, fewer samples than cells (or fewer distinct ones), no cells, non-finite
/// samples, a bad tolerance.
pub fn generalized_lloyd(
    samples: &[f64],
    dim: usize,
    cells: usize,
    max_iterations: usize,
    tolerance: f64,
    seed: u64,
) -> Result<(Codebook, QuantiserReport), SimError> {
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    lloyd_with(samples, dim, cells, max_iterations, tolerance, &mut rng)
}

fn lloyd_with(
    samples: &[f64],
    dim: usize,
    cells: usize,
    max_iterations: usize,
    tolerance: f64,
    rng: &mut Pcg64Mcg,
) -> Result<(Codebook, QuantiserReport), SimError> {
    require!(
        (1..=MAX_DIMS).contains(&dim),
        "samples",
        format!("vectors need 1 to {MAX_DIMS} dimensions, got {dim}"),
    );
    require!(
        samples.len().is_multiple_of(dim),
        "samples",
        format!("{} values are not whole vectors of {dim}", samples.len()),
    );
    let n = samples.len() / dim;
    if cells == 0 {
        return Err(ConfigError::invalid("vqql.cells", "must be at least 1").into());
    }
    require!(
        n >= cells,
        "vqql.samples",
        format!("must be at least cells = {cells}, got {n}"),
    );
    if max_iterations == 0 {
        return Err(ConfigError::invalid("vqql.lloyd_iterations", "must be at least 1").into());
    }
    require!(
        tolerance >= 0.0 && tolerance.is_finite(),
        "vqql.lloyd_tolerance",
        format!("must be a finite number >= 0, got {tolerance}"),
    );
    if let Some(k) = samples.iter().position(|v| !v.is_finite()) {
        return Err(ConfigError::invalid(
            "samples",
            format!("sample {} element {} is not finite", k / dim, k % dim),
        )
        .into());
    }
    let scale = standard_scale(samples, dim);
    let weights: Vec<f64> = scale.iter().map(|s| 1.0 / s).collect();
    // Scaled exactly as the codebook scales (x * (1 / s)).
    let scaled: Vec<f64> = samples
        .iter()
        .enumerate()
        .map(|(k, v)| v * weights[k % dim])
        .collect();
    if scaled.iter().any(|v| !v.is_finite()) {
        return Err(ConfigError::invalid("samples", "too large to standardise").into());
    }
    let centroids: Vec<f64> = seed_plus_plus(&scaled, dim, cells, rng)?
        .into_iter()
        .flat_map(|i| samples[i * dim..(i + 1) * dim].iter().copied())
        .collect();
    iterate(
        samples,
        &scaled,
        dim,
        &scale,
        centroids,
        max_iterations,
        tolerance,
    )
}

/// The Lloyd iterations from the initial `centroids` (row-major, in the samples' units) on
/// checked samples and their scaled copy.
fn iterate(
    samples: &[f64],
    scaled: &[f64],
    dim: usize,
    scale: &[f64],
    mut centroids: Vec<f64>,
    max_iterations: usize,
    tolerance: f64,
) -> Result<(Codebook, QuantiserReport), SimError> {
    let n = samples.len() / dim;
    let cells = centroids.len() / dim;
    let weights: Vec<f64> = scale.iter().map(|s| 1.0 / s).collect();
    let x = |i: usize| &samples[i * dim..(i + 1) * dim];
    let z = |i: usize| &scaled[i * dim..(i + 1) * dim];
    let mut labels = vec![0usize; n];
    let mut counts = vec![0usize; cells];
    let mut sums = vec![0.0; cells * dim];
    let mut far = vec![0.0; n];
    let mut history: Vec<f64> = Vec::new();
    let mut reseeded = 0;
    loop {
        let book = Codebook::from_flat(dim, centroids.clone(), scale.to_vec())?;
        counts.fill(0);
        let mut total = 0.0;
        for i in 0..n {
            let (j, d) = book.nearest_unchecked(x(i));
            labels[i] = j;
            counts[j] += 1;
            total += d;
        }
        let distortion = total / n as f64;
        let converged = distortion == 0.0
            || history
                .last()
                .is_some_and(|&prev| prev - distortion <= tolerance * prev);
        history.push(distortion);
        let full = counts.iter().all(|&c| c > 0);
        if full && (converged || history.len() >= max_iterations) {
            let report = QuantiserReport {
                samples: n,
                cells,
                iterations: history.len(),
                converged,
                distortion,
                distortion_history: history,
                reseeded,
                cell_sizes: [
                    counts.iter().copied().min().unwrap_or(0),
                    counts.iter().copied().max().unwrap_or(0),
                ],
            };
            return Ok((book, report));
        }
        require!(
            history.len() < max_iterations + MAX_REPAIR_ITERATIONS,
            "vqql.cells",
            format!(
                "{} of {cells} cells stayed empty after {} Lloyd iterations",
                counts.iter().filter(|&&c| c == 0).count(),
                history.len()
            ),
        );
        // Means, summed in sample order.
        sums.fill(0.0);
        for i in 0..n {
            let j = labels[i];
            for (s, v) in sums[j * dim..(j + 1) * dim].iter_mut().zip(x(i)) {
                *s += v;
            }
        }
        for j in 0..cells {
            if counts[j] > 0 {
                let c = counts[j] as f64;
                for e in 0..dim {
                    centroids[j * dim + e] = sums[j * dim + e] / c;
                }
            }
        }
        if !full {
            // Distances to the updated centroids, then re-seed every empty cell at the
            // sample farthest from every centroid placed so far.
            let mut cz = vec![0.0; dim];
            for i in 0..n {
                let j = labels[i];
                for e in 0..dim {
                    cz[e] = centroids[j * dim + e] * weights[e];
                }
                far[i] = sq_dist(z(i), &cz);
            }
            for j in 0..cells {
                if counts[j] > 0 {
                    continue;
                }
                let mut s = 0;
                for i in 1..n {
                    if far[i] > far[s] {
                        s = i;
                    }
                }
                require!(
                    far[s] > 0.0,
                    "vqql.samples",
                    format!("too few distinct states to fill {cells} cells"),
                );
                centroids[j * dim..(j + 1) * dim].copy_from_slice(x(s));
                reseeded += 1;
                let zs = z(s).to_vec();
                for i in 0..n {
                    let d = sq_dist(z(i), &zs);
                    if d < far[i] {
                        far[i] = d;
                    }
                }
            }
        }
    }
}

/// Builds every agent's codebook (see the [module docs](self)): explores the point-mass task
/// from `starts` and quantises each agent's own states. Returns the codebook features and
/// the per-agent reports. Errors: invalid settings or starts (naming the field).
pub fn build_codebook(
    model: &PointMass,
    starts: &Starts,
    config: &VqqlConfig,
) -> Result<(FeatureSpace, LloydReport), SimError> {
    config.validate()?;
    starts.validate(model)?;
    let mut rng = Pcg64Mcg::seed_from_u64(config.seed);
    let per_agent = explore(
        model,
        starts,
        config.samples,
        config.explore_steps,
        &mut rng,
    )?;
    quantise(&per_agent, &vec![4; per_agent.len()], config, &mut rng)
}

/// Every agent's codebook of its samples (`dims[i]` values each), agent 0 first.
fn quantise(
    per_agent: &[Vec<f64>],
    dims: &[usize],
    config: &VqqlConfig,
    rng: &mut Pcg64Mcg,
) -> Result<(FeatureSpace, LloydReport), SimError> {
    let mut books = Vec::with_capacity(per_agent.len());
    let mut reports = Vec::with_capacity(per_agent.len());
    for (samples, &dim) in per_agent.iter().zip(dims) {
        let (book, report) = lloyd_with(
            samples,
            dim,
            config.cells,
            config.lloyd_iterations,
            config.lloyd_tolerance,
            rng,
        )?;
        books.push(book);
        reports.push(report);
    }
    let features = FeatureSpace::codebook(books)?;
    let report = LloydReport::new(reports, &features);
    Ok((features, report))
}

/// [`build_codebook`] on any environment: explores it with [`explore_env`] (episodes of
/// [`explore_steps`](VqqlConfig::explore_steps)) and quantises each agent's observations.
pub fn build_codebook_on<E: Environment>(
    env: &mut E,
    config: &VqqlConfig,
) -> Result<(FeatureSpace, LloydReport), SimError> {
    config.validate()?;
    let mut rng = Pcg64Mcg::seed_from_u64(config.seed);
    let per_agent = explore_env(env, config.samples, config.explore_steps, &mut rng)?;
    quantise(
        &per_agent,
        &(0..env.n_agents())
            .map(|i| env.obs_dim(i))
            .collect::<Vec<_>>(),
        config,
        &mut rng,
    )
}

/// VQQL on the point-mass task: [`build_codebook`], then tabular Q-learning over the cells
/// ([`train_fql`] with the codebook features) from `starts` with the learning settings `fql`.
pub fn train_vqql(
    model: &PointMass,
    starts: &Starts,
    vqql: &VqqlConfig,
    fql: &FqlConfig,
    progress: impl crate::learn::fql::Observer,
) -> Result<(FqlOutcome, LloydReport), SimError> {
    fql.validate()?;
    let (features, report) = build_codebook(model, starts, vqql)?;
    let outcome = train_fql(model, &features, starts, fql, progress)?;
    Ok((outcome, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::pointmass::PointMassConfig;

    fn samples(count: usize, seed: u64) -> Vec<f64> {
        let model = PointMass::paper();
        let starts = Starts::Uniform {
            position: 6.0,
            velocity: 1.0,
        };
        let mut rng = Pcg64Mcg::seed_from_u64(seed);
        explore(&model, &starts, count, 50, &mut rng)
            .unwrap()
            .swap_remove(0)
    }

    /// Cell sizes under the brute-force nearest centroid (lowest index on ties).
    fn brute_force_sizes(book: &Codebook, samples: &[f64]) -> Vec<usize> {
        let mut sizes = vec![0; book.n_cells()];
        for x in samples.chunks(book.dim()) {
            sizes[book.nearest_brute_force(x).0] += 1;
        }
        sizes
    }

    #[test]
    fn lloyd_is_deterministic_fills_every_cell_and_never_increases_distortion() {
        let data = samples(3000, 1);
        assert_eq!(data.len(), 3000 * 4);
        let (a, ra) = generalized_lloyd(&data, 4, 60, 40, 0.0, 5).unwrap();
        let (b, rb) = generalized_lloyd(&data, 4, 60, 40, 0.0, 5).unwrap();
        assert_eq!(a, b);
        assert_eq!(ra, rb);
        let bits = |c: &Codebook| {
            c.centroids()
                .iter()
                .map(|v| v.to_bits())
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&a), bits(&b));
        let (c, _) = generalized_lloyd(&data, 4, 60, 40, 0.0, 6).unwrap();
        assert_ne!(bits(&a), bits(&c), "another seed, other centroids");

        // Every cell holds a sample; the report's sizes and distortion are those of the final
        // codebook.
        let sizes = brute_force_sizes(&a, &data);
        assert!(sizes.iter().all(|&s| s > 0), "{sizes:?}");
        assert_eq!(
            ra.cell_sizes,
            [*sizes.iter().min().unwrap(), *sizes.iter().max().unwrap()]
        );
        let mean: f64 = data
            .chunks(4)
            .map(|x| a.nearest_brute_force(x).1)
            .sum::<f64>()
            / 3000.0;
        assert!(
            (mean - ra.distortion).abs() <= 1e-12 * mean,
            "{mean} vs {}",
            ra.distortion
        );
        assert_eq!(ra.distortion_history.last(), Some(&ra.distortion));
        assert_eq!(ra.iterations, ra.distortion_history.len());
        assert!(ra.iterations > 2);
        for w in ra.distortion_history.windows(2) {
            assert!(w[1] <= w[0] * (1.0 + 1e-12), "{:?}", ra.distortion_history);
        }
        assert!(ra.distortion_history[0] > ra.distortion);
        assert_eq!((ra.samples, ra.cells), (3000, 60));

        // The scale standardises: velocities weigh like positions.
        let scale = a.scale();
        assert!(scale[0] > 2.0 && scale[2] < scale[0], "{scale:?}");
        // A loose tolerance stops earlier.
        let (_, loose) = generalized_lloyd(&data, 4, 60, 40, 0.05, 5).unwrap();
        assert!(loose.converged && loose.iterations < ra.iterations);
    }

    #[test]
    fn empty_cells_are_reseeded_deterministically() {
        // Two identical initial centroids: every sample picks the first (lowest index), so the
        // second cell is empty after the first assignment and is re-seeded at the sample
        // farthest from the updated first centroid (11, from 4.5); then 0-3 and 10-11 split.
        let data: Vec<f64> = [0.0, 1.0, 2.0, 3.0, 10.0, 11.0].to_vec();
        let scale = vec![1.0];
        let (book, report) = iterate(&data, &data, 1, &scale, vec![1.0, 1.0], 10, 0.0).unwrap();
        assert_eq!(report.reseeded, 1);
        assert!(brute_force_sizes(&book, &data).iter().all(|&s| s > 0));
        let mut c = book.centroids().to_vec();
        c.sort_by(f64::total_cmp);
        assert_eq!(c, [1.5, 10.5]);
        // (2.25 + 0.25 + 0.25 + 2.25 + 0.25 + 0.25) / 6.
        assert!((report.distortion - 5.5 / 6.0).abs() < 1e-15);
        for w in report.distortion_history.windows(2) {
            assert!(w[1] <= w[0]);
        }
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let data = samples(200, 2);
        let err = |r: Result<(Codebook, QuantiserReport), SimError>| {
            r.expect_err("expected an error").to_string()
        };
        assert!(err(generalized_lloyd(&data, 4, 0, 10, 0.0, 0)).starts_with("vqql.cells:"));
        assert!(err(generalized_lloyd(&data, 4, 201, 10, 0.0, 0)).starts_with("vqql.samples:"));
        assert!(err(generalized_lloyd(&data, 0, 2, 10, 0.0, 0)).starts_with("samples:"));
        assert!(err(generalized_lloyd(&data, 17, 2, 10, 0.0, 0)).starts_with("samples:"));
        assert!(err(generalized_lloyd(&data[..7], 4, 1, 10, 0.0, 0)).starts_with("samples:"));
        assert!(
            err(generalized_lloyd(&data, 4, 2, 10, f64::NAN, 0))
                .starts_with("vqql.lloyd_tolerance:")
        );
        let mut nan = data.clone();
        nan[13] = f64::NAN;
        let text = err(generalized_lloyd(&nan, 4, 2, 10, 0.0, 0));
        assert!(text.contains("sample 3 element 1"), "{text}");
        // Fewer distinct samples than cells.
        let same = [1.0, 2.0, 3.0, 4.0].repeat(50);
        let text = err(generalized_lloyd(&same, 4, 2, 10, 0.0, 0));
        assert!(text.contains("distinct"), "{text}");
        // One distinct sample and one cell is fine.
        let (book, report) = generalized_lloyd(&same, 4, 1, 10, 0.0, 0).unwrap();
        assert_eq!(book.centroid(0), Some(&[1.0, 2.0, 3.0, 4.0][..]));
        assert_eq!(report.distortion, 0.0);

        let bad = |f: fn(&mut VqqlConfig)| {
            let mut c = VqqlConfig::default();
            f(&mut c);
            c.validate().unwrap_err().to_string()
        };
        assert!(bad(|c| c.cells = 0).starts_with("vqql.cells:"));
        assert!(bad(|c| c.samples = 10).starts_with("vqql.samples:"));
        assert!(bad(|c| c.explore_steps = 0).starts_with("vqql.explore_steps:"));
        assert!(bad(|c| c.lloyd_iterations = 0).starts_with("vqql.lloyd_iterations:"));
        assert!(bad(|c| c.lloyd_tolerance = -1.0).starts_with("vqql.lloyd_tolerance:"));
        assert!(VqqlConfig::default().validate().is_ok());
        let parsed: VqqlConfig = toml::from_str("cells = 10\nseed = 3").unwrap();
        assert_eq!((parsed.cells, parsed.seed), (10, 3));
        assert_eq!(parsed.samples, VqqlConfig::default().samples);
        assert!(toml::from_str::<VqqlConfig>("cels = 10").is_err());

        // build_codebook checks the starts and the settings first.
        let model = PointMass::paper();
        let bad_starts = Starts::Uniform {
            position: f64::NAN,
            velocity: 0.0,
        };
        let text = build_codebook(&model, &bad_starts, &VqqlConfig::default())
            .unwrap_err()
            .to_string();
        assert!(text.starts_with("starts.position:"), "{text}");
        let small = VqqlConfig {
            cells: 0,
            ..VqqlConfig::default()
        };
        let text = build_codebook(
            &model,
            &crate::learn::tasks::pointmass::default_starts(),
            &small,
        )
        .unwrap_err()
        .to_string();
        assert!(text.starts_with("vqql.cells:"), "{text}");
    }

    #[test]
    fn build_codebook_quantises_each_agent_and_is_deterministic() {
        let model = PointMass::new(PointMassConfig::default()).unwrap();
        let config = VqqlConfig {
            cells: 40,
            samples: 2000,
            explore_steps: 40,
            lloyd_iterations: 30,
            lloyd_tolerance: 1e-6,
            seed: 9,
        };
        let starts = crate::learn::tasks::pointmass::default_starts();
        let (features, report) = build_codebook(&model, &starts, &config).unwrap();
        let (again, report2) = build_codebook(&model, &starts, &config).unwrap();
        assert_eq!(features, again);
        assert_eq!(report, report2);
        assert!(features.is_codebook());
        assert_eq!(features.n_agents(), 2);
        assert_eq!(features.n_cores(1), Some(40));
        assert_eq!(features.obs_dim(0), Some(4));
        assert_ne!(features.codebooks()[0], features.codebooks()[1]);
        assert_eq!(report.agents.len(), 2);
        assert_eq!(report.codebook_values, 2 * (40 * 4 + 4));
        assert_eq!(
            report.iterations,
            report.agents.iter().map(|a| a.iterations).max().unwrap()
        );
        assert!(report.agents.iter().all(|a| a.cell_sizes[0] >= 1));
        // The default matches the paper's fuzzy layout parameter for parameter.
        let fuzzy = crate::learn::tasks::pointmass::feature_space(
            &model,
            &crate::paper::POSITION_CORES,
            &crate::paper::VELOCITY_CORES,
        )
        .unwrap();
        assert_eq!(fuzzy.n_cores(0), Some(VqqlConfig::default().cells));
        assert_eq!(fuzzy.n_params(&[25, 25]).unwrap(), 101_250);
    }
}
