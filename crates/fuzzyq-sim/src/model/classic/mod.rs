//! The classic single-agent benchmarks of fuzzy Q-iteration: the problems of Busoniu, Babuska,
//! De Schutter and Ernst, *Reinforcement Learning and Dynamic Programming Using Function
//! Approximators* (CRC Press, 2010), chapter 4, as implemented in its companion MATLAB toolbox
//! ApproxRL (Lucian Busoniu, 2010).
//!
//! - [`dcmotor`]: the DC motor (`dc_problem` with the linear, saturated model `dc_linmdp` and
//!   the LQR reward): state `[alpha, alpha_dot]`, voltage `u`, the exact zero-order-hold
//!   discretisation.
//! - [`pendulum`]: the inverted pendulum swing-up (`ipsetup_problem`, type `ip`, LQR reward):
//!   a weight on a DC motor's disc that the motor alone cannot lift in one go, integrated with
//!   one classical RK4 step per sample time, angle wrapped to `[-pi, pi)`.
//!
//! Each model implements [`fuzzyq_core::Model`] for `f32` and `f64` (one agent, one action
//! component), computes in `f64` whatever the solver's precision, and comes with named
//! [`Preset`]s: the grid, actions, `gamma` and stopping threshold of a toolbox run. The
//! `"toolbox-demo"` presets are the configurations the parity tests check transition by
//! transition, sweep by sweep and step by step against the toolbox run under GNU Octave
//! (`tests/it/approxrl.rs`, data and provenance in `tests/data/approxrl/`).
//!
//! # Conventions shared with the toolbox
//! - The reward is evaluated at the **current** state with the applied action:
//!   `rho(x, u) = -x' Q x - R u^2`.
//! - Grids are built the way the toolbox builds them, with Octave's colon ranges
//!   ([`colon`], [`symequidgrid`]): the cores are the same doubles, bit for bit.
//! - The toolbox numbers cores in MATLAB's column-major order (first state variable fastest);
//!   fuzzyq numbers them row-major (last variable fastest). [`toolbox_core_index`] and
//!   [`core_index_from_toolbox`] convert.

pub mod arm;
pub mod carhill;
pub mod dcmotor;
pub mod pendulum;

pub use dcmotor::{DcMotor, DcMotorConfig};
pub use pendulum::{Pendulum, PendulumConfig};

use fuzzyq_core::Real;
use fuzzyq_core::solver::{Grid, SolverConfig};
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError};

/// The most RK4 substeps per sample time a configuration may ask for.
pub const MAX_RK4_SUBSTEPS: usize = 10_000;

/// How a classic model integrates one sample time.
///
/// In a config file: `integrator = "zoh"` or `integrator = { rk4 = { substeps = 1 } }`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", deny_unknown_fields)]
pub enum Integrator {
    /// The exact zero-order-hold discretisation (linear models only).
    Zoh,
    /// Classical fourth-order Runge-Kutta with the action held constant.
    Rk4 {
        /// Steps per sample time (1 to [`MAX_RK4_SUBSTEPS`]). The step sizes are the
        /// differences of Octave's range `0 : Ts/substeps : Ts`, as the toolbox's fixed-step
        /// integration uses them.
        substeps: usize,
    },
}

impl Integrator {
    /// Checks the substep count.
    pub fn validate(&self, field: &str) -> Result<(), ConfigError> {
        match *self {
            Self::Zoh => Ok(()),
            Self::Rk4 { substeps } if (1..=MAX_RK4_SUBSTEPS).contains(&substeps) => Ok(()),
            Self::Rk4 { substeps } => Err(ConfigError::invalid(
                field,
                format!("rk4 substeps must be between 1 and {MAX_RK4_SUBSTEPS}, got {substeps}"),
            )),
        }
    }
}

/// A named problem setup: the fuzzy grid, the discrete actions, the discount factor and the
/// stopping threshold of a toolbox run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Preset {
    /// The preset's name (`"toolbox-demo"`, `"fine"`).
    pub name: String,
    /// The cores of each state variable, in increasing order.
    pub cores: Vec<Vec<f64>>,
    /// The discrete actions (one component each), in increasing order.
    pub actions: Vec<f64>,
    /// Discount factor, in `[0, 1)`.
    pub gamma: f64,
    /// Stopping threshold on `||theta_k - theta_{k-1}||_inf` (the toolbox's `eps`).
    pub xi: f64,
}

impl Preset {
    /// Checks the grid, actions, `gamma` and `xi`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.cores.is_empty() {
            return Err(ConfigError::invalid(
                "preset.cores",
                "needs at least one state variable",
            ));
        }
        for (dim, c) in self.cores.iter().enumerate() {
            if c.len() < 2 {
                return Err(ConfigError::invalid(
                    "preset.cores",
                    format!(
                        "state variable {dim} needs at least 2 cores, got {}",
                        c.len()
                    ),
                ));
            }
            if c.iter().any(|v| !v.is_finite()) || c.windows(2).any(|w| w[0] >= w[1]) {
                return Err(ConfigError::invalid(
                    "preset.cores",
                    format!("the cores of state variable {dim} must be finite and increasing"),
                ));
            }
        }
        validate_actions("preset.actions", &self.actions)?;
        if !(self.gamma >= 0.0 && self.gamma < 1.0) {
            return Err(ConfigError::invalid(
                "preset.gamma",
                format!("must be in [0, 1), got {}", self.gamma),
            ));
        }
        if !(self.xi > 0.0 && self.xi.is_finite()) {
            return Err(ConfigError::invalid(
                "preset.xi",
                format!("must be a positive number, got {}", self.xi),
            ));
        }
        Ok(())
    }

    /// Number of joint cores (the product of the per-variable core counts).
    #[must_use]
    pub fn n_cores(&self) -> usize {
        self.cores.iter().map(Vec::len).product()
    }

    /// The fuzzy grid in precision `T` (triangular memberships).
    pub fn grid<T: Real>(&self) -> Result<Grid<T>, SimError> {
        self.validate()?;
        let cores = self
            .cores
            .iter()
            .map(|c| c.iter().map(|&v| T::from_f64(v)).collect())
            .collect();
        Ok(Grid::new(cores)?)
    }

    /// The toolbox's iteration: synchronous plain sweeps from `theta_0 = 0` with the preset's
    /// `gamma` and `xi` and the toolbox's limit of 1000 iterations (no extrapolation).
    #[must_use]
    pub fn solver_config(&self) -> SolverConfig {
        SolverConfig {
            gamma: self.gamma,
            xi: self.xi,
            max_sweeps: 1000,
            extrapolate: false,
            ..SolverConfig::default()
        }
    }
}

/// Checks a discrete action list: 1 to 4096 finite values.
pub(crate) fn validate_actions(field: &str, actions: &[f64]) -> Result<(), ConfigError> {
    if actions.is_empty() || actions.len() > 4096 {
        return Err(ConfigError::invalid(
            field,
            format!("needs 1 to 4096 actions, got {}", actions.len()),
        ));
    }
    if let Some(a) = actions.iter().find(|a| !a.is_finite()) {
        return Err(ConfigError::invalid(
            field,
            format!("must be finite numbers, got {a}"),
        ));
    }
    Ok(())
}

/// Checks that `v` is a positive finite number.
pub(crate) fn positive(field: &str, v: f64) -> Result<(), ConfigError> {
    if v > 0.0 && v.is_finite() {
        Ok(())
    } else {
        Err(ConfigError::invalid(
            field,
            format!("must be a positive number, got {v}"),
        ))
    }
}

/// Checks that `v` is a non-negative finite number.
pub(crate) fn non_negative(field: &str, v: f64) -> Result<(), ConfigError> {
    if v >= 0.0 && v.is_finite() {
        Ok(())
    } else {
        Err(ConfigError::invalid(
            field,
            format!("must be a non-negative number, got {v}"),
        ))
    }
}

/// Octave's colon range `base : increment : limit`, element for element as Octave 7 computes
/// it: the number of elements with Octave's tolerant floor (Hagerty's FL5, tolerance
/// `3 eps`), element `i` as `base + i * increment` and the last element clipped to `limit`
/// when it overshoots (so `-pi : 5*pi/180 : pi` ends exactly at `pi`).
///
/// An empty range (`increment` of the wrong sign) is an empty vector. Non-finite arguments and
/// ranges of more than 2^24 elements are refused.
pub fn colon(base: f64, increment: f64, limit: f64) -> Result<Vec<f64>, ConfigError> {
    if !(base.is_finite() && increment.is_finite() && limit.is_finite()) {
        return Err(ConfigError::invalid(
            "range",
            format!("{base} : {increment} : {limit} has a non-finite bound or increment"),
        ));
    }
    if increment == 0.0 || (limit < base && increment > 0.0) || (limit > base && increment < 0.0) {
        return Ok(Vec::new());
    }
    if (limit <= base && base + increment < limit) || (limit >= base && base + increment > limit) {
        return Ok(vec![base]);
    }
    let n = colon_numel(base, limit, increment);
    if n > 1 << 24 {
        return Err(ConfigError::invalid(
            "range",
            format!("{base} : {increment} : {limit} has {n} elements (at most 2^24)"),
        ));
    }
    if n <= 1 {
        return Ok(if n == 1 { vec![base] } else { Vec::new() });
    }
    let mut last = base + (n - 1) as f64 * increment;
    if (increment > 0.0 && last >= limit) || (increment < 0.0 && last <= limit) {
        last = limit;
    }
    if base.round() == base && increment.round() == increment {
        last = last.round();
    }
    let mut out = Vec::with_capacity(n);
    out.push(base);
    out.extend((1..n - 1).map(|i| base + i as f64 * increment));
    out.push(last);
    Ok(out)
}

/// Octave's `xnumel_internal`: the element count of a non-empty finite range.
fn colon_numel(base: f64, limit: f64, inc: f64) -> usize {
    let ct = 3.0 * f64::EPSILON;
    let tmp = tolerant_floor((limit - base + inc) / inc, ct);
    let mut n = if tmp > 0.0 { tmp as i64 } else { 0 };
    let teq = |u: f64, v: f64| (u - v).abs() < u.abs().max(v.abs()) * ct;
    if !teq(base + (n - 1) as f64 * inc, limit) {
        if teq(base + (n - 2) as f64 * inc, limit) {
            n -= 1;
        } else if teq(base + n as f64 * inc, limit) {
            n += 1;
        }
    }
    n.max(0) as usize
}

/// Hagerty's FL5 tolerant floor, as in Octave's `xtfloor`.
fn tolerant_floor(x: f64, ct: f64) -> f64 {
    let q = if x < 0.0 { 1.0 - ct } else { 1.0 };
    let rmax = q / (2.0 - ct);
    let mut t1 = 1.0 + x.floor();
    t1 = (ct / q) * t1.abs();
    t1 = t1.min(rmax);
    t1 = t1.max(ct);
    t1 = (x + t1).floor();
    if x <= 0.0 || (t1 - x) < rmax {
        t1
    } else {
        t1 - 1.0
    }
}

/// The toolbox's `symequidgrid(n, b)`: `n` equidistant points on `[-b, b]`, computed as
/// Octave's range `-b : 2*b/(n-1) : b` (so the doubles are Octave's: point `i` is
/// `-b + i * (2b/(n-1))`, which is not exactly symmetric about 0, and the last is `b`).
pub fn symequidgrid(b: f64, n: usize) -> Result<Vec<f64>, ConfigError> {
    if !(b > 0.0 && b.is_finite() && (2..=1 << 24).contains(&n)) {
        return Err(ConfigError::invalid(
            "symequidgrid",
            format!("needs a positive finite bound and 2 to 2^24 points, got b = {b}, n = {n}"),
        ));
    }
    let grid = colon(-b, 2.0 * b / (n - 1) as f64, b)?;
    if grid.len() != n {
        return Err(ConfigError::invalid(
            "symequidgrid",
            format!("Octave's range gives {} points instead of {n}", grid.len()),
        ));
    }
    Ok(grid)
}

/// Octave's `linspace(x1, x2, n)` (built symmetrically from both ends, as Octave 7 does).
fn linspace(x1: f64, x2: f64, n: usize) -> Vec<f64> {
    match n {
        0 => return Vec::new(),
        1 => return vec![x2],
        _ => {}
    }
    let mut out = vec![0.0; n];
    out[0] = x1;
    out[n - 1] = x2;
    let delta = (x2 - x1) / (n - 1) as f64;
    for i in 1..n / 2 {
        out[i] = x1 + i as f64 * delta;
        out[n - 1 - i] = x2 - i as f64 * delta;
    }
    if !n.is_multiple_of(2) {
        out[n / 2] = if x1 == -x2 { 0.0 } else { (x1 + x2) / 2.0 };
    }
    out
}

/// The toolbox's `symloggrid(n, b, sp, ep)`: `n` (odd) points on `[-b, b]`, logarithmically
/// denser near 0: `ls = (logspace(sp, ep, (n+1)/2) - 10^sp) / (10^ep - 10^sp)` and the sorted
/// union of `-b ls` and `b ls`. Computed with Octave's `linspace` and `10^x` through the
/// platform's `pow`; the values agree with Octave's to the last bit where the two `pow`s do.
pub fn symloggrid(n: usize, b: f64, sp: f64, ep: f64) -> Result<Vec<f64>, ConfigError> {
    if n.is_multiple_of(2) || !(3..=1 << 20).contains(&n) {
        return Err(ConfigError::invalid(
            "symloggrid",
            format!("needs an odd number of points between 3 and 2^20, got {n}"),
        ));
    }
    if !(b > 0.0 && b.is_finite() && sp.is_finite() && ep.is_finite() && sp < ep) {
        return Err(ConfigError::invalid(
            "symloggrid",
            format!("needs b > 0 and finite powers sp < ep, got b = {b}, sp = {sp}, ep = {ep}"),
        ));
    }
    let (lo, hi) = (10f64.powf(sp), 10f64.powf(ep));
    let ls: Vec<f64> = linspace(sp, ep, n.div_ceil(2))
        .into_iter()
        .map(|e| (10f64.powf(e) - lo) / (hi - lo))
        .collect();
    let mut grid: Vec<f64> = ls
        .iter()
        .map(|&l| -b * l)
        .chain(ls.iter().map(|&l| b * l))
        .collect();
    grid.sort_by(f64::total_cmp);
    // sortx: drop an element when the next one is not larger (the duplicate zero).
    let mut out: Vec<f64> = grid
        .windows(2)
        .filter(|w| w[1] > w[0])
        .map(|w| w[0])
        .collect();
    out.push(grid[grid.len() - 1]);
    for v in &mut out {
        if *v == 0.0 {
            *v = 0.0; // +0, whichever zero sorted last
        }
    }
    if out.len() != n || out.windows(2).any(|w| w[0] >= w[1]) {
        return Err(ConfigError::invalid(
            "symloggrid",
            format!("the grid has {} distinct points instead of {n}", out.len()),
        ));
    }
    Ok(out)
}

/// The toolbox's (column-major) flat index of the core with row-major (fuzzyq) flat index
/// `index` on a grid with `dims[e]` cores per state variable. `None` if out of range.
#[must_use]
pub fn toolbox_core_index(dims: &[usize], index: usize) -> Option<usize> {
    let n: usize = dims.iter().product();
    if index >= n {
        return None;
    }
    let (mut rest, mut out, mut stride) = (index, 0, 1);
    // Row-major digits come out last variable first; column-major strides grow from the first.
    let mut digits = vec![0usize; dims.len()];
    for (d, &len) in digits.iter_mut().zip(dims).rev() {
        *d = rest % len;
        rest /= len;
    }
    for (&d, &len) in digits.iter().zip(dims) {
        out += d * stride;
        stride *= len;
    }
    Some(out)
}

/// The row-major (fuzzyq) flat index of the core with the toolbox's (column-major) flat index
/// `index`. `None` if out of range.
#[must_use]
pub fn core_index_from_toolbox(dims: &[usize], index: usize) -> Option<usize> {
    let n: usize = dims.iter().product();
    if index >= n {
        return None;
    }
    let (mut rest, mut out) = (index, 0);
    let mut digits = vec![0usize; dims.len()];
    for (d, &len) in digits.iter_mut().zip(dims) {
        *d = rest % len;
        rest /= len;
    }
    for (&d, &len) in digits.iter().zip(dims) {
        out = out * len + d;
    }
    Some(out)
}

/// The step sizes of `substeps` fixed steps over `[0, ts]`: the differences of Octave's range
/// `0 : ts/substeps : ts` (uniform `ts/substeps` if that range has an unexpected length).
pub(crate) fn rk4_step_sizes(ts: f64, substeps: usize) -> Vec<f64> {
    let substeps = substeps.max(1);
    match colon(0.0, ts / substeps as f64, ts) {
        Ok(t) if t.len() == substeps + 1 => t.windows(2).map(|w| w[1] - w[0]).collect(),
        _ => vec![ts / substeps as f64; substeps],
    }
}

/// Classical RK4 over the step sizes `h` for a 2-state ODE `y' = f(y)` (the action is held
/// inside `f`), written like MATLAB's `ode4`:
/// `y + (h/6) (k1 + 2 k2 + 2 k3 + k4)` with `k2 = f(y + 0.5 h k1)`, ...
pub(crate) fn rk4(f: impl Fn([f64; 2]) -> [f64; 2], y0: [f64; 2], h: &[f64]) -> [f64; 2] {
    let mut y = y0;
    for &hi in h {
        let add = |c: f64, k: [f64; 2]| [y[0] + c * k[0], y[1] + c * k[1]];
        let k1 = f(y);
        let k2 = f(add(0.5 * hi, k1));
        let k3 = f(add(0.5 * hi, k2));
        let k4 = f(add(hi, k3));
        let c = hi / 6.0;
        for j in 0..2 {
            y[j] += c * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
        }
    }
    y
}

/// MATLAB/Octave's `sat(x, lo, hi)`: `x` limited to `[lo, hi]` (NaN stays NaN).
#[inline]
pub(crate) fn sat(x: f64, lo: f64, hi: f64) -> f64 {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colon_matches_octave_ranges() {
        assert_eq!(
            colon(-10.0, 5.0, 10.0).unwrap(),
            [-10.0, -5.0, 0.0, 5.0, 10.0]
        );
        assert_eq!(colon(-3.0, 1.5, 3.0).unwrap(), [-3.0, -1.5, 0.0, 1.5, 3.0]);
        // Octave's classic example: 1.8:0.05:1.9 has 3 elements.
        assert_eq!(colon(1.8, 0.05, 1.9).unwrap().len(), 3);
        assert!(colon(1.0, 1.0, 0.0).unwrap().is_empty());
        assert_eq!(colon(0.0, 2.0, 1.0).unwrap(), [0.0]);
        let pi = std::f64::consts::PI;
        let fine = colon(-pi, 5.0 * pi / 180.0, pi).unwrap();
        assert_eq!(fine.len(), 73);
        assert_eq!((fine[0], fine[72]), (-pi, pi));
        assert_eq!(colon(-16.0 * pi, pi / 6.0, 16.0 * pi).unwrap().len(), 193);
        assert_eq!(colon(-15.0 * pi, pi / 3.0, 15.0 * pi).unwrap().len(), 91);
        assert!(colon(0.0, f64::NAN, 1.0).is_err());
    }

    #[test]
    fn symequidgrid_is_octaves_range() {
        let pi = std::f64::consts::PI;
        let g = symequidgrid(15.0 * pi, 21).unwrap();
        // Not symmetric: element 11 is -b + 11 inc, not -(element 9).
        assert_eq!(g[9], -4.712_388_980_384_688);
        assert_eq!(g[11], 4.712_388_980_384_695);
        assert_eq!(g[10], 0.0);
        assert!(symequidgrid(1.0, 1).is_err());
        assert!(symequidgrid(-1.0, 3).is_err());
    }

    #[test]
    fn symloggrid_gives_the_pendulum_actions() {
        let u = symloggrid(15, 3.0, -1.0, 1.0).unwrap();
        assert_eq!(u.len(), 15);
        assert_eq!((u[0], u[7], u[14]), (-3.0, 0.0, 3.0));
        for i in 0..15 {
            assert_eq!(u[i], -u[14 - i]);
        }
        assert!(symloggrid(4, 3.0, -1.0, 1.0).is_err());
    }

    #[test]
    fn core_index_conversions_invert() {
        let dims = [3, 4, 2];
        for i in 0..24 {
            let t = toolbox_core_index(&dims, i).unwrap();
            assert_eq!(core_index_from_toolbox(&dims, t), Some(i));
        }
        // Row-major (i0, i1, i2) = (1, 2, 1): 1*8 + 2*2 + 1 = 13; column-major 1 + 3*2 + 12*1.
        assert_eq!(toolbox_core_index(&dims, 13), Some(19));
        assert_eq!(toolbox_core_index(&dims, 24), None);
    }

    #[test]
    fn integrator_serde_is_lowercase() {
        #[derive(Deserialize, Serialize)]
        struct W {
            integrator: Integrator,
        }
        let w: W = toml::from_str("integrator = \"zoh\"").unwrap();
        assert_eq!(w.integrator, Integrator::Zoh);
        let w: W = toml::from_str("integrator = { rk4 = { substeps = 4 } }").unwrap();
        assert_eq!(w.integrator, Integrator::Rk4 { substeps: 4 });
        assert!(toml::from_str::<W>("integrator = { rk4 = { steps = 4 } }").is_err());
        assert!(
            Integrator::Rk4 { substeps: 0 }
                .validate("env.integrator")
                .is_err()
        );
    }
}
