//! The walled arena of the robot experiments and its obstacles, read from TOML.
//!
//! The arena is a rectangle bounded by walls; obstacles are boxes (optionally rotated) and
//! discs. The same description builds the rapier colliders of the physics plants
//! ([`crate::world`]) and answers the geometric questions of the models that learn on it
//! (does a robot disc at this pose touch anything; how far does a ray go), so that the model a
//! policy is trained on and the plant it runs on see the same world.
//!
//! ```toml
//! # the paper's 12 m x 12 m surface with one obstacle
//! x = [-6.0, 6.0]
//! y = [-6.0, 6.0]
//!
//! [[obstacle]]
//! shape = "box"
//! center = [-2.0, 2.5]
//! half_extents = [0.6, 0.05]
//! angle_deg = 38.66
//!
//! [[obstacle]]
//! shape = "disc"
//! center = [2.0, -2.0]
//! radius = 0.3
//! ```

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError, require};
use crate::toml_doc::TomlDoc;

/// One obstacle.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(tag = "shape", rename_all = "snake_case", deny_unknown_fields)]
pub enum Obstacle {
    /// A rectangle of half extents `half_extents`, rotated by `angle_deg` counter-clockwise.
    Box {
        /// Centre (m).
        center: [f64; 2],
        /// Half width and half height before rotation (m).
        half_extents: [f64; 2],
        /// Rotation (degrees, counter-clockwise).
        #[serde(default)]
        angle_deg: f64,
    },
    /// A disc.
    Disc {
        /// Centre (m).
        center: [f64; 2],
        /// Radius (m).
        radius: f64,
    },
}

/// An obstacle as written: its fields are read in place (not through serde's buffer of an
/// internally tagged enum, which forgets where they are), so that an error names the field's
/// line.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObstacle {
    shape: Shape,
    center: [f64; 2],
    half_extents: Option<[f64; 2]>,
    angle_deg: Option<f64>,
    radius: Option<f64>,
}

#[derive(Deserialize)]
#[serde(rename_all = "snake_case")]
enum Shape {
    Box,
    Disc,
}

impl<'de> Deserialize<'de> for Obstacle {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let raw = RawObstacle::deserialize(d)?;
        match raw.shape {
            Shape::Box => {
                if raw.radius.is_some() {
                    return Err(D::Error::custom(
                        "unknown field `radius` for a box (a disc has it), expected `center`, \
                         `half_extents` or `angle_deg`",
                    ));
                }
                Ok(Self::Box {
                    center: raw.center,
                    half_extents: raw
                        .half_extents
                        .ok_or_else(|| D::Error::missing_field("half_extents"))?,
                    angle_deg: raw.angle_deg.unwrap_or(0.0),
                })
            }
            Shape::Disc => {
                if let Some(field) = [
                    ("half_extents", raw.half_extents.is_some()),
                    ("angle_deg", raw.angle_deg.is_some()),
                ]
                .iter()
                .find_map(|&(f, given)| given.then_some(f))
                {
                    return Err(D::Error::custom(format!(
                        "unknown field `{field}` for a disc (a box has it), expected `center` or \
                         `radius`"
                    )));
                }
                Ok(Self::Disc {
                    center: raw.center,
                    radius: raw
                        .radius
                        .ok_or_else(|| D::Error::missing_field("radius"))?,
                })
            }
        }
    }
}

/// A rectangular walled arena with obstacles.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Arena {
    /// The walls' x range `[lo, hi]` (m).
    pub x: [f64; 2],
    /// The walls' y range `[lo, hi]` (m).
    pub y: [f64; 2],
    /// Obstacles inside the walls.
    #[serde(default, rename = "obstacle")]
    pub obstacles: Vec<Obstacle>,
}

impl Default for Arena {
    /// The paper's open arena: walls at +-6 m, no obstacles.
    fn default() -> Self {
        Self {
            x: [-6.0, 6.0],
            y: [-6.0, 6.0],
            obstacles: Vec::new(),
        }
    }
}

fn finite(field: &str, v: &[f64]) -> Result<(), ConfigError> {
    match v.iter().find(|v| !v.is_finite()) {
        Some(bad) => Err(ConfigError::invalid(
            field,
            format!("must be finite, found {bad}"),
        )),
        None => Ok(()),
    }
}

impl Arena {
    /// Reads and validates an arena file. Errors are one line naming the file, the field and
    /// its line: `arena.toml: x: has 3 values ([-6, 0, 6]), expected 2 (line 1)`.
    pub fn from_file(path: &Path) -> Result<Self, SimError> {
        let text = crate::fs::read_text(path, crate::fs::MAX_TEXT_BYTES).map_err(|e| {
            ConfigError::invalid("arena", format!("cannot read {}: {e}", path.display()))
        })?;
        Self::from_toml(&text).map_err(|e| match e {
            SimError::Config(e) => ConfigError::Parse(format!("{}: {e}", path.display())).into(),
            other => other,
        })
    }

    /// Parses and validates an arena from TOML text (errors name the field and its line).
    pub fn from_toml(text: &str) -> Result<Self, SimError> {
        let doc = TomlDoc::parse(text).map_err(|e| ConfigError::Parse(format!("arena: {e}")))?;
        let arena: Self = doc
            .deserialize()
            .map_err(|e| ConfigError::Parse(format!("arena: {e}")))?;
        // Validation names fields `arena.x`, `arena.obstacle[1]`: in the file, `x`.
        arena.validate().map_err(|e| match e {
            ConfigError::Invalid { field, reason } => {
                let line = doc.line_of(field.strip_prefix("arena.").unwrap_or(&field));
                ConfigError::Invalid {
                    field,
                    reason: match line {
                        Some(line) => format!("{reason} (line {line})"),
                        None => reason,
                    },
                }
            }
            other => other,
        })?;
        Ok(arena)
    }

    /// The arena as TOML text.
    #[must_use]
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("an arena serialises")
    }

    /// Checks that the walls enclose a non-empty area and every obstacle is well formed.
    pub fn validate(&self) -> Result<(), ConfigError> {
        finite("arena.x", &self.x)?;
        finite("arena.y", &self.y)?;
        require!(
            self.x[0] < self.x[1] && self.y[0] < self.y[1],
            "arena",
            format!(
                "walls must satisfy lo < hi, found x = {:?}, y = {:?}",
                self.x, self.y
            ),
        );
        for (i, o) in self.obstacles.iter().enumerate() {
            let field = format!("arena.obstacle[{i}]");
            match o {
                Obstacle::Box {
                    center,
                    half_extents,
                    angle_deg,
                } => {
                    finite(&field, center)?;
                    finite(&field, half_extents)?;
                    finite(&field, &[*angle_deg])?;
                    require!(
                        half_extents.iter().all(|&h| h > 0.0),
                        &field,
                        format!("half_extents must be positive, found {half_extents:?}"),
                    );
                }
                Obstacle::Disc { center, radius } => {
                    finite(&field, center)?;
                    finite(&field, &[*radius])?;
                    require!(
                        *radius > 0.0,
                        &field,
                        format!("radius must be positive, found {radius}"),
                    );
                }
            }
            let walls = || format!("the walls x = {:?}, y = {:?}", self.x, self.y);
            require!(
                self.overlaps_inside(o),
                &field,
                format!("{} lies entirely outside {}", describe(o), walls()),
            );
            require!(
                !self
                    .corners()
                    .iter()
                    .all(|&c| obstacle_distance(o, c) == 0.0),
                &field,
                format!("{} covers the whole arena within {}", describe(o), walls()),
            );
        }
        Ok(())
    }

    /// The four corners of the walls' rectangle.
    fn corners(&self) -> [[f64; 2]; 4] {
        let ([x0, x1], [y0, y1]) = (self.x, self.y);
        [[x0, y0], [x1, y0], [x1, y1], [x0, y1]]
    }

    /// Whether obstacle `o` covers some of the inside of the walls (more than a touch).
    fn overlaps_inside(&self, o: &Obstacle) -> bool {
        let ([x0, x1], [y0, y1]) = (self.x, self.y);
        match o {
            Obstacle::Disc { center, radius } => {
                let near = [center[0].clamp(x0, x1), center[1].clamp(y0, y1)];
                (near[0] - center[0]).hypot(near[1] - center[1]) < *radius
            }
            Obstacle::Box {
                center,
                half_extents: [hx, hy],
                angle_deg,
            } => {
                // Separating axes: the rectangle's two and the box's two.
                let (s, c) = angle_deg.to_radians().sin_cos();
                let corners = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]].map(|[a, b]| {
                    [
                        center[0] + c * a * hx - s * b * hy,
                        center[1] + s * a * hx + c * b * hy,
                    ]
                });
                let span = |pts: &[[f64; 2]], axis: [f64; 2]| {
                    pts.iter()
                        .map(|p| p[0] * axis[0] + p[1] * axis[1])
                        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
                            (lo.min(v), hi.max(v))
                        })
                };
                let walls = self.corners();
                [[1.0, 0.0], [0.0, 1.0], [c, s], [-s, c]]
                    .iter()
                    .all(|&axis| {
                        let (a0, a1) = span(&corners, axis);
                        let (b0, b1) = span(&walls, axis);
                        a0 < b1 && b0 < a1
                    })
            }
        }
    }

    /// Whether a disc of radius `r` centred at `c` touches a wall or an obstacle.
    #[must_use]
    pub fn disc_collides(&self, c: [f64; 2], r: f64) -> bool {
        if c[0] - r < self.x[0]
            || c[0] + r > self.x[1]
            || c[1] - r < self.y[0]
            || c[1] + r > self.y[1]
        {
            return true;
        }
        self.obstacles.iter().any(|o| obstacle_within(o, c, r))
    }

    /// Distance from `origin` along the unit direction `dir` to the first wall or obstacle, if
    /// within `max_range` (an exact reference for the physics plant's ray casts).
    #[must_use]
    pub fn ray_distance(&self, origin: [f64; 2], dir: [f64; 2], max_range: f64) -> Option<f64> {
        let mut best = f64::INFINITY;
        // Walls: the ray starts inside, so it leaves through the first wall it meets.
        for (k, (lo, hi)) in [(self.x[0], self.x[1]), (self.y[0], self.y[1])]
            .into_iter()
            .enumerate()
        {
            if dir[k] > 0.0 {
                best = best.min((hi - origin[k]) / dir[k]);
            } else if dir[k] < 0.0 {
                best = best.min((lo - origin[k]) / dir[k]);
            }
        }
        for o in &self.obstacles {
            if let Some(t) = ray_obstacle(o, origin, dir) {
                best = best.min(t);
            }
        }
        (best <= max_range).then_some(best.max(0.0))
    }
}

/// An obstacle in words: `disc at (2, 0) of radius 0.5`.
fn describe(o: &Obstacle) -> String {
    match o {
        Obstacle::Box {
            center,
            half_extents,
            angle_deg,
        } => format!(
            "box at ({}, {}) of half extents ({}, {}) at {angle_deg} degrees",
            center[0], center[1], half_extents[0], half_extents[1]
        ),
        Obstacle::Disc { center, radius } => {
            format!("disc at ({}, {}) of radius {radius}", center[0], center[1])
        }
    }
}

/// Rotates `p` by `-angle` (into a box's frame).
fn to_local(p: [f64; 2], center: [f64; 2], angle_deg: f64) -> [f64; 2] {
    let (s, c) = angle_deg.to_radians().sin_cos();
    let d = [p[0] - center[0], p[1] - center[1]];
    [c * d[0] + s * d[1], -s * d[0] + c * d[1]]
}

/// Relative margin of [`norm_clearly_below`]: far beyond the few roundings on either side
/// (each at most `2^-52` relative), far below any distance the models tell apart.
const NORM_MARGIN: f64 = 1e-9;

/// Whether `dx.hypot(dy) < t`, decided by the squared norm: `Some(true)` or `Some(false)`
/// when `dx^2 + dy^2` is clearly below or above `t^2` (by the relative [`NORM_MARGIN`]),
/// `None` near the boundary (and for non-finite or extreme inputs), where only `hypot`
/// itself decides. A square root and the care `hypot` takes against overflow cost more
/// than the rest of the robots' reward, evaluated at every one of their 37.7M cores.
pub(crate) fn norm_clearly_below(dx: f64, dy: f64, t: f64) -> Option<bool> {
    let (s, t2) = (dx * dx + dy * dy, t * t);
    if !(t > 0.0 && s.is_finite() && t2.is_finite() && t2 >= f64::MIN_POSITIVE) {
        return None;
    }
    if s < t2 * (1.0 - NORM_MARGIN) {
        Some(true)
    } else if s > t2 * (1.0 + NORM_MARGIN) {
        Some(false)
    } else {
        None
    }
}

/// `obstacle_distance(o, p) < r`: the same answer, without `hypot` away from the boundary.
fn obstacle_within(o: &Obstacle, p: [f64; 2], r: f64) -> bool {
    let (d, radius) = obstacle_offset(o, p);
    norm_clearly_below(d[0], d[1], radius + r).unwrap_or_else(|| distance_of(o, d, radius) < r)
}

/// Distance from a point to an obstacle (0 inside).
fn obstacle_distance(o: &Obstacle, p: [f64; 2]) -> f64 {
    let (d, radius) = obstacle_offset(o, p);
    distance_of(o, d, radius)
}

/// The offset `d` of `p` from obstacle `o`'s nearest point (a box's) or centre (a disc's),
/// and the disc's radius (0 for a box).
fn obstacle_offset(o: &Obstacle, p: [f64; 2]) -> ([f64; 2], f64) {
    match o {
        Obstacle::Box {
            center,
            half_extents,
            angle_deg,
        } => {
            let q = to_local(p, *center, *angle_deg);
            let dx = (q[0].abs() - half_extents[0]).max(0.0);
            let dy = (q[1].abs() - half_extents[1]).max(0.0);
            ([dx, dy], 0.0)
        }
        Obstacle::Disc { center, radius } => ([p[0] - center[0], p[1] - center[1]], *radius),
    }
}

/// The distance from an obstacle of a point at offset `d` ([`obstacle_offset`]).
fn distance_of(o: &Obstacle, d: [f64; 2], radius: f64) -> f64 {
    match o {
        Obstacle::Box { .. } => d[0].hypot(d[1]),
        Obstacle::Disc { .. } => (d[0].hypot(d[1]) - radius).max(0.0),
    }
}

/// Entry distance of a ray into an obstacle (`None` if it misses or starts inside).
fn ray_obstacle(o: &Obstacle, origin: [f64; 2], dir: [f64; 2]) -> Option<f64> {
    match o {
        Obstacle::Box {
            center,
            half_extents,
            angle_deg,
        } => {
            let p = to_local(origin, *center, *angle_deg);
            let (s, c) = angle_deg.to_radians().sin_cos();
            let d = [c * dir[0] + s * dir[1], -s * dir[0] + c * dir[1]];
            // Slab test.
            let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
            for k in 0..2 {
                if d[k] == 0.0 {
                    if p[k].abs() > half_extents[k] {
                        return None;
                    }
                } else {
                    let a = (-half_extents[k] - p[k]) / d[k];
                    let b = (half_extents[k] - p[k]) / d[k];
                    t0 = t0.max(a.min(b));
                    t1 = t1.min(a.max(b));
                }
            }
            (t0 <= t1 && t0 >= 0.0).then_some(t0)
        }
        Obstacle::Disc { center, radius } => {
            let m = [origin[0] - center[0], origin[1] - center[1]];
            let b = m[0] * dir[0] + m[1] * dir[1];
            let c = m[0] * m[0] + m[1] * m[1] - radius * radius;
            let disc = b * b - c;
            if c < 0.0 || disc < 0.0 {
                return None;
            }
            let t = -b - disc.sqrt();
            (t >= 0.0).then_some(t)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points at distance `t (1 + e)` from `c` in many directions, for relative offsets `e`
    /// from far inside to far outside, through the boundary's last bits.
    fn around(c: [f64; 2], t: f64) -> Vec<[f64; 2]> {
        let offsets = [
            -0.5, -1e-6, -1e-9, -1e-12, -1e-15, 0.0, 1e-15, 1e-12, 1e-9, 1e-6, 0.5,
        ];
        let mut pts = Vec::new();
        for k in 0..64 {
            let (s, co) = (f64::from(k) * 0.1).sin_cos();
            for e in offsets {
                let d = t * (1.0 + e);
                let p = [c[0] + d * co, c[1] + d * s];
                pts.push(p);
                pts.push([f64::from_bits(p[0].to_bits() + 1), p[1]]);
                pts.push([p[0], f64::from_bits(p[1].to_bits() - 1)]);
            }
        }
        pts
    }

    /// The squared-norm filter never contradicts `hypot`, and decides away from the boundary.
    #[test]
    fn the_norm_filter_agrees_with_hypot() {
        for t in [0.14, 0.07, 1.0, 3.5e-3, 250.0] {
            let mut decided = 0;
            for p in around([0.3, -1.7], t) {
                let (dx, dy) = (p[0] - 0.3, p[1] + 1.7);
                if let Some(below) = norm_clearly_below(dx, dy, t) {
                    assert_eq!(below, dx.hypot(dy) < t, "t {t}, d ({dx}, {dy})");
                    decided += 1;
                }
            }
            assert!(decided > 64 * 4 * 3, "t {t}: only {decided} decided");
        }
        for (dx, dy, t) in [(1.0, 1.0, 0.0), (1.0, 0.0, -1.0), (f64::NAN, 0.0, 1.0)] {
            assert_eq!(norm_clearly_below(dx, dy, t), None);
        }
        assert_eq!(norm_clearly_below(1e300, 1e300, 1.0), None);
    }

    /// Collision tests with the filter answer as the distance itself does, at and around the
    /// boundary of a disc obstacle, a rotated box and another robot.
    #[test]
    fn filtered_collision_tests_match_the_distance() {
        let r = 0.07;
        let disc = Obstacle::Disc {
            center: [1.0, -2.0],
            radius: 0.5,
        };
        for p in around([1.0, -2.0], 0.5 + r) {
            assert_eq!(
                obstacle_within(&disc, p, r),
                obstacle_distance(&disc, p) < r
            );
        }
        let boxed = Obstacle::Box {
            center: [0.0, 2.0],
            half_extents: [1.0, 0.5],
            angle_deg: 30.0,
        };
        let corner = {
            let (s, c) = 30f64.to_radians().sin_cos();
            [c - s * 0.5, 2.0 + s + c * 0.5]
        };
        for p in around(corner, r)
            .into_iter()
            .chain(around([0.0, 2.0], 1.0 + r))
        {
            assert_eq!(
                obstacle_within(&boxed, p, r),
                obstacle_distance(&boxed, p) < r
            );
        }
        for p in around([0.5, 0.5], 2.0 * r) {
            assert_eq!(
                crate::model::khepera::robots_overlap([0.5, 0.5], p, r),
                (p[0] - 0.5).hypot(p[1] - 0.5) < 2.0 * r
            );
        }
    }

    const DOC: &str = r#"
x = [-6.0, 6.0]
y = [-6.0, 6.0]

[[obstacle]]
shape = "box"
center = [0.0, 2.0]
half_extents = [1.0, 0.5]

[[obstacle]]
shape = "disc"
center = [3.0, 0.0]
radius = 0.5
"#;

    #[test]
    fn parses_and_answers_geometry() {
        let a = Arena::from_toml(DOC).unwrap();
        assert_eq!(a.obstacles.len(), 2);
        // Rays by hand: up from the origin hits the box's lower face at y = 1.5.
        assert_eq!(a.ray_distance([0.0, 0.0], [0.0, 1.0], 10.0), Some(1.5));
        // Right hits the disc at x = 2.5.
        assert_eq!(a.ray_distance([0.0, 0.0], [1.0, 0.0], 10.0), Some(2.5));
        // Left hits the wall at x = -6, beyond a 2 m range.
        assert_eq!(a.ray_distance([0.0, 0.0], [-1.0, 0.0], 10.0), Some(6.0));
        assert_eq!(a.ray_distance([0.0, 0.0], [-1.0, 0.0], 2.0), None);
        assert!(a.disc_collides([0.0, 1.0], 0.6));
        assert!(!a.disc_collides([0.0, 1.0], 0.4));
        assert!(a.disc_collides([5.95, 0.0], 0.07));
        assert!(!a.disc_collides([-5.0, -5.0], 0.07));
        assert!(a.disc_collides([3.0, 0.6], 0.2));
    }

    #[test]
    fn rotated_box() {
        let a = Arena {
            obstacles: vec![Obstacle::Box {
                center: [0.0, 0.0],
                half_extents: [1.0, 0.1],
                angle_deg: 90.0,
            }],
            ..Arena::default()
        };
        // Rotated upright: the ray along +x meets its face at x = 0.1 from x = -1.
        let t = a.ray_distance([-1.0, 0.0], [1.0, 0.0], 5.0).unwrap();
        assert!((t - 0.9).abs() < 1e-12, "{t}");
        assert!(a.disc_collides([0.0, 0.9], 0.05));
        assert!(!a.disc_collides([0.5, 0.0], 0.3));
    }

    #[test]
    fn bad_input_names_the_field() {
        let e = Arena::from_toml("x = [1.0, -1.0]\ny = [-1.0, 1.0]").unwrap_err();
        assert!(e.to_string().contains("arena"), "{e}");
        let e = Arena::from_toml(
            "x = [-1.0, 1.0]\ny = [-1.0, 1.0]\n[[obstacle]]\nshape = \"disc\"\ncenter = [0.0, 0.0]\nradius = -1.0",
        )
        .unwrap_err();
        assert!(e.to_string().contains("obstacle[0]"), "{e}");
        let e = Arena::from_toml("x = [-1.0, 1.0]\ny = [-1.0, 1.0]\nwall = 3").unwrap_err();
        assert!(e.to_string().contains("wall"), "{e}");
    }

    /// `x = [-6, 0, 6]` is refused as the configuration refuses it under `[env.arena]` (toml
    /// alone would read `[-6, 0]`).
    #[test]
    fn extra_numbers_are_refused() {
        let e = Arena::from_toml("x = [-6, 0, 6]\ny = [-6.0, 6.0]").unwrap_err();
        assert_eq!(
            e.to_string(),
            "arena: x: has 3 values ([-6, 0, 6]), expected 2 (line 1)"
        );
        let e = Arena::from_toml(
            "x = [-6, 6]\ny = [-6, 6]\n[[obstacle]]\nshape = \"disc\"\ncenter = [1, 2, 3]\nradius = 1",
        )
        .unwrap_err();
        assert_eq!(
            e.to_string(),
            "arena: obstacle[0].center: has 3 values ([1, 2, 3]), expected 2 (line 5)"
        );
    }

    /// Errors inside an obstacle name the field's line, not the `[[obstacle]]` line.
    #[test]
    fn obstacle_errors_name_the_field_line() {
        let text = DOC.replace("radius = 0.5", "radius = \"big\"");
        let e = Arena::from_toml(&text).unwrap_err().to_string();
        assert_eq!(
            e,
            "arena: obstacle[1].radius: invalid type: string \"big\", expected f64 (line 13)"
        );
        let e = Arena::from_toml(&DOC.replace("radius = 0.5", "radius = 0.5\nangle_deg = 3"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("unknown field `angle_deg` for a disc") && e.ends_with("(line 14)"),
            "{e}"
        );
        let e = Arena::from_toml(&DOC.replace("shape = \"disc\"", "shape = \"blob\""))
            .unwrap_err()
            .to_string();
        assert!(e.contains("blob") && e.ends_with("(line 11)"), "{e}");
        let e = Arena::from_toml(&DOC.replace("half_extents = [1.0, 0.5]\n", ""))
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing field `half_extents`"), "{e}");
    }

    /// Obstacles entirely outside the walls, or covering the whole arena, are refused, naming
    /// the obstacle, the walls and the line.
    #[test]
    fn obstacles_outside_or_covering_everything_are_refused() {
        let with = |obstacle: &str| {
            Arena::from_toml(&format!("{DOC}\n[[obstacle]]\n{obstacle}\n"))
                .map_err(|e| e.to_string())
        };
        let e = with("shape = \"disc\"\ncenter = [20.0, 0.0]\nradius = 1.0").unwrap_err();
        assert_eq!(
            e,
            "arena.obstacle[2]: disc at (20, 0) of radius 1 lies entirely outside the walls \
             x = [-6.0, 6.0], y = [-6.0, 6.0] (line 15)"
        );
        let e =
            with("shape = \"box\"\ncenter = [0.0, 0.0]\nhalf_extents = [7.0, 6.0]").unwrap_err();
        assert!(
            e.contains("obstacle[2]: box") && e.contains("covers the whole arena"),
            "{e}"
        );
        let e = with("shape = \"disc\"\ncenter = [0.0, 0.0]\nradius = 9.0").unwrap_err();
        assert!(e.contains("covers the whole arena"), "{e}");
        // A thin box beyond the corner: its bounding box overlaps the arena, the box does not.
        let e = with(
            "shape = \"box\"\ncenter = [6.4, 6.4]\nhalf_extents = [2.0, 0.05]\nangle_deg = -45.0",
        )
        .unwrap_err();
        assert!(e.contains("entirely outside"), "{e}");
        // Only touching a wall from outside is outside too.
        let e = with("shape = \"disc\"\ncenter = [7.0, 0.0]\nradius = 1.0").unwrap_err();
        assert!(e.contains("entirely outside"), "{e}");
        // Through a wall, across a corner, and the same box turned into the arena: accepted.
        with("shape = \"disc\"\ncenter = [6.5, 0.0]\nradius = 1.0").unwrap();
        with("shape = \"box\"\ncenter = [6.0, 6.0]\nhalf_extents = [0.5, 0.5]\nangle_deg = 30.0")
            .unwrap();
        with("shape = \"box\"\ncenter = [6.4, 6.4]\nhalf_extents = [2.0, 0.05]\nangle_deg = 45.0")
            .unwrap();
        // A wall-to-wall box leaves room beside it.
        with("shape = \"box\"\ncenter = [0.0, 0.0]\nhalf_extents = [7.0, 1.0]").unwrap();
        // The same check guards arenas built in code (and configurations).
        let a = Arena {
            obstacles: vec![Obstacle::Disc {
                center: [0.0, 100.0],
                radius: 1.0,
            }],
            ..Arena::default()
        };
        assert!(
            a.validate()
                .unwrap_err()
                .to_string()
                .contains("obstacle[0]")
        );
    }

    #[test]
    fn file_errors_name_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.toml");
        std::fs::write(&path, "x = [-6, 0, 6]\ny = [-6.0, 6.0]").unwrap();
        let e = Arena::from_file(&path).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("{}: arena: x: has 3", path.display())),
            "{e}"
        );
        std::fs::write(&path, "x = [6.0, -6.0]\ny = [-6.0, 6.0]").unwrap();
        let e = Arena::from_file(&path).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("{}: arena: walls", path.display())),
            "{e}"
        );
    }
}
