//! Octave's arithmetic, reproduced where the ApproxRL toolbox's results depend on it: colon
//! ranges, the toolbox's grid builders, `linspace`, fixed-step RK4 and the two angle wrappings
//! the toolbox's models use. Each is documented against the Octave (or MATLAB) expression it
//! reproduces; the parity tests (`tests/it/approxrl.rs`) check the results bit for bit.

use std::f64::consts::PI;

use crate::error::{ConfigError, require};

/// Octave's colon range `base : increment : limit`, element for element as Octave 7 computes
/// it: the number of elements with Octave's tolerant floor (Hagerty's FL5, tolerance
/// `3 eps`), element `i` as `base + i * increment` and the last element clipped to `limit`
/// when it overshoots (so `-pi : 5*pi/180 : pi` ends exactly at `pi`).
///
/// An empty range (`increment` of the wrong sign) is an empty vector. Non-finite arguments and
/// ranges of more than 2^24 elements are refused.
pub fn colon(base: f64, increment: f64, limit: f64) -> Result<Vec<f64>, ConfigError> {
    require!(
        base.is_finite() && increment.is_finite() && limit.is_finite(),
        "range",
        format!("{base} : {increment} : {limit} has a non-finite bound or increment"),
    );
    if increment == 0.0 || (limit < base && increment > 0.0) || (limit > base && increment < 0.0) {
        return Ok(Vec::new());
    }
    if (limit <= base && base + increment < limit) || (limit >= base && base + increment > limit) {
        return Ok(vec![base]);
    }
    let n = colon_numel(base, limit, increment);
    require!(
        n <= 1 << 24,
        "range",
        format!("{base} : {increment} : {limit} has {n} elements (at most 2^24)"),
    );
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
    require!(
        b > 0.0 && b.is_finite() && (2..=1 << 24).contains(&n),
        "symequidgrid",
        format!("needs a positive finite bound and 2 to 2^24 points, got b = {b}, n = {n}"),
    );
    let grid = colon(-b, 2.0 * b / (n - 1) as f64, b)?;
    require!(
        grid.len() == n,
        "symequidgrid",
        format!("Octave's range gives {} points instead of {n}", grid.len()),
    );
    Ok(grid)
}

/// Octave's `linspace(x1, x2, n)` (built symmetrically from both ends, as Octave 7 does, so
/// the middle point of a symmetric range is exactly 0).
#[must_use]
pub fn linspace(x1: f64, x2: f64, n: usize) -> Vec<f64> {
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
    require!(
        !n.is_multiple_of(2) && (3..=1 << 20).contains(&n),
        "symloggrid",
        format!("needs an odd number of points between 3 and 2^20, got {n}"),
    );
    require!(
        b > 0.0 && b.is_finite() && sp.is_finite() && ep.is_finite() && sp < ep,
        "symloggrid",
        format!("needs b > 0 and finite powers sp < ep, got b = {b}, sp = {sp}, ep = {ep}"),
    );
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
    require!(
        out.len() == n && !out.windows(2).any(|w| w[0] >= w[1]),
        "symloggrid",
        format!("the grid has {} distinct points instead of {n}", out.len()),
    );
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

/// MATLAB's `mod(alpha + pi, 2*pi) - pi` with Octave's `mod` (`x - floor(x/y) y`, 0 when
/// `x/y` is within a relative `eps` of an integer, the sign of `y`): the angle wrapped into
/// `[-pi, pi)` (rounding can give `pi` itself for angles a hair below `-pi`).
#[must_use]
pub fn wrap_angle_octave(alpha: f64) -> f64 {
    octave_mod(alpha + PI, 2.0 * PI) - PI
}

/// Octave's `mod(x, y)` for doubles (`lo-mappers.h`).
fn octave_mod(x: f64, y: f64) -> f64 {
    let mut r = if y == 0.0 {
        x
    } else {
        let q = x / y;
        let nq = nint(q);
        if nint(y) != y && ((q - nq) / nq).abs() < f64::EPSILON {
            0.0
        } else {
            x - y * q.floor()
        }
    };
    if x != y && y != 0.0 {
        r = r.copysign(y);
    }
    r
}

/// Octave's `x_nint`: `floor(x + 0.5)` for finite `x`.
fn nint(x: f64) -> f64 {
    if x.is_finite() { (x + 0.5).floor() } else { x }
}

/// `mod(a + pi, 2 pi) - pi` with MATLAB's plain `mod` (`a - floor(a / m) m`), as the arm's
/// toolbox code wraps its angles: `[-pi, pi)` up to rounding at the ends (unlike
/// [`wrap_angle_octave`], no snapping of near-integer quotients). NaN stays NaN.
#[must_use]
pub fn wrap_angle_floor(a: f64) -> f64 {
    let m = 2.0 * PI;
    let s = a + PI;
    (s - (s / m).floor() * m) - PI
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
    fn octave_wrapping_matches_octaves_mod() {
        assert_eq!(wrap_angle_octave(PI), -PI);
        assert_eq!(wrap_angle_octave(-PI), -PI);
        assert_eq!(wrap_angle_octave(0.5), 0.5);
        assert!((wrap_angle_octave(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-15);
        assert!((wrap_angle_octave(-3.2) - (2.0 * PI - 3.2)).abs() < 1e-15);
        let w = wrap_angle_octave(-PI - 1e-17);
        assert!((-PI..=PI).contains(&w));
    }
}
