//! Khepera IV robots as colliding discs with ray-cast sonars (see the [module docs](super)).

use fuzzyq_core::EvalError;
use fuzzyq_core::error::check_len;
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64Mcg;

use rapier2d::prelude::{QueryFilter, Ray};

use super::contacts::{Collisions, StepContacts};
use super::engine::*;
use crate::error::{ConfigError, SimError, require};
use crate::model::khepera::{self, KheperaConfig, MAX_ROBOTS};

// ---------------------------------------------------------------------------------------------
// Khepera robots
// ---------------------------------------------------------------------------------------------

/// Khepera IV robots as colliding discs with sonars (see the [module docs](crate::world)).
pub struct KheperaWorld {
    config: KheperaConfig,
    substeps: usize,
    engine: Engine,
    poses: Vec<[f64; 3]>,
    velocities: Vec<[f64; 2]>,
    placed: bool,
    collisions: Collisions,
    rng: Pcg64Mcg,
    wheel_noise: Option<Normal<f64>>,
    sonar_noise: Option<Normal<f64>>,
}

impl std::fmt::Debug for KheperaWorld {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KheperaWorld")
            .field("config", &self.config)
            .field("substeps", &self.substeps)
            .field("poses", &self.poses)
            .field("collisions", &self.collisions)
            .finish_non_exhaustive()
    }
}

impl KheperaWorld {
    /// The default number of substeps per control step.
    pub const DEFAULT_SUBSTEPS: usize = 8;

    /// Builds the world of `config` (validated) with 8 substeps per control step; `seed` seeds
    /// the noise. The robots are parked outside the arena until [`reset`](Self::reset).
    pub fn new(config: &KheperaConfig, seed: u64) -> Result<Self, SimError> {
        Self::with_substeps(config, Self::DEFAULT_SUBSTEPS, seed)
    }

    /// [`new`](Self::new) with `substeps` substeps per control step.
    pub fn with_substeps(
        config: &KheperaConfig,
        substeps: usize,
        seed: u64,
    ) -> Result<Self, SimError> {
        config.validate()?;
        require!(
            (1..=MAX_SUBSTEPS).contains(&substeps),
            "plant.substeps",
            format!("must be between 1 and {MAX_SUBSTEPS}, got {substeps}"),
        );
        let a = &config.arena;
        let n = config.agents;
        let engine = Engine::new(
            [a.x[0], a.x[1], a.y[0], a.y[1]],
            &a.obstacles,
            n,
            config.radius,
            KHEPERA_MASS,
            false,
        );
        let poses = engine
            .robots
            .iter()
            .map(|r| {
                let p = engine.world.bodies[r.body].translation();
                [f64::from(p.x), f64::from(p.y), 0.0]
            })
            .collect();
        let normal = |std: f64| (std > 0.0).then(|| Normal::new(0.0, std).ok()).flatten();
        Ok(Self {
            substeps,
            engine,
            poses,
            velocities: vec![[0.0; 2]; n],
            placed: false,
            collisions: Collisions::new(n),
            rng: Pcg64Mcg::seed_from_u64(seed),
            wheel_noise: normal(config.noise.wheel_std),
            sonar_noise: normal(config.noise.sonar_std),
            config: config.clone(),
        })
    }

    /// The configuration.
    #[must_use]
    pub fn config(&self) -> &KheperaConfig {
        &self.config
    }

    /// Places the robots at rest at `poses` (`[x, y, heading]`, one per robot) and clears the
    /// collision counts. Fails, naming the robot, if one overlaps a wall, an obstacle or
    /// another robot (touching is allowed).
    pub fn reset(&mut self, poses: &[[f64; 3]]) -> Result<(), SimError> {
        let n = self.config.agents;
        check_len("poses", n, poses.len())?;
        let r = self.config.radius;
        for (i, p) in poses.iter().enumerate() {
            if let Some(index) = p.iter().position(|v| !v.is_finite()) {
                return Err(EvalError::NotFinite {
                    what: "poses",
                    index: 3 * i + index,
                }
                .into());
            }
            require!(
                !self.config.arena.disc_collides([p[0], p[1]], r),
                &format!("poses[{i}]"),
                format!(
                    "robot {i} at ({}, {}) overlaps a wall or an obstacle",
                    p[0], p[1]
                ),
            );
            for (j, q) in poses[..i].iter().enumerate() {
                require!(
                    !khepera::robots_overlap([p[0], p[1]], [q[0], q[1]], r),
                    &format!("poses[{i}]"),
                    format!("robot {i} overlaps robot {j}"),
                );
            }
        }
        self.poses = poses
            .iter()
            .map(|p| [p[0], p[1], khepera::wrap_heading(p[2])])
            .collect();
        self.velocities = vec![[0.0; 2]; n];
        self.engine.place(&self.poses);
        self.collisions = Collisions::new(n);
        self.placed = true;
        Ok(())
    }

    /// Advances one control step with wheel speeds `wheels[r] = [v_l, v_r]` per robot (with
    /// the configured wheel noise, then limited to `+-max_wheel_speed`); returns the contacts
    /// that started.
    pub fn step(&mut self, wheels: &[[f64; 2]]) -> Result<StepContacts, SimError> {
        let n = self.config.agents;
        check_len("wheels", n, wheels.len())?;
        if let Some(index) = wheels.iter().flatten().position(|v| !v.is_finite()) {
            return Err(EvalError::NotFinite {
                what: "wheels",
                index,
            }
            .into());
        }
        if !self.placed {
            return Err(ConfigError::invalid("poses", "reset the world before stepping").into());
        }
        let vmax = self.config.max_wheel_speed;
        let mut w = [[0.0; 2]; MAX_ROBOTS];
        for (wi, given) in w.iter_mut().zip(wheels) {
            for (a, &b) in wi.iter_mut().zip(given) {
                let noisy = match &self.wheel_noise {
                    Some(d) => b * (1.0 + d.sample(&mut self.rng)),
                    None => b,
                };
                *a = noisy.clamp(-vmax, vmax);
            }
        }
        let k = self.substeps;
        let t = self.config.sample_time;
        let h = t / k as f64;
        let base = self.config.wheel_base;
        let start: Vec<[f64; 3]> = self.poses.clone();
        let mut motions = [Motion::default(); MAX_ROBOTS];
        let mut outcomes = [Outcome::default(); MAX_ROBOTS];
        let mut targets = [[0.0; 3]; MAX_ROBOTS];
        let mut contacts = StepContacts::default();
        for _ in 0..k {
            for i in 0..n {
                let p = self.poses[i];
                let q = khepera::drive(p, w[i], base, h);
                targets[i] = q;
                motions[i] = Motion {
                    pos: [p[0], p[1]],
                    angle: p[2],
                    linvel: [(q[0] - p[0]) / h, (q[1] - p[1]) / h],
                    angvel: khepera::wrap_heading(q[2] - p[2]) / h,
                };
            }
            self.engine
                .substep(h, &motions[..n], &mut outcomes[..n], &mut contacts.starts);
            for i in 0..n {
                let (o, q) = (&outcomes[i], targets[i]);
                let xy = if o.linear { o.pos } else { [q[0], q[1]] };
                let heading = if o.angular {
                    khepera::wrap_heading(o.angle)
                } else {
                    q[2]
                };
                self.poses[i] = [xy[0], xy[1], heading];
            }
        }
        for i in 0..n {
            self.velocities[i] = [
                (self.poses[i][0] - start[i][0]) / t,
                (self.poses[i][1] - start[i][1]) / t,
            ];
        }
        self.collisions.add(&contacts);
        Ok(contacts)
    }

    /// Poses `[x, y, heading]` of the robots (heading in `(-pi, pi]`).
    #[must_use]
    pub fn poses(&self) -> &[[f64; 3]] {
        &self.poses
    }

    /// Linear velocity `[v_x, v_y]` of each robot over the last control step (displacement
    /// divided by the sample time; zero after a reset).
    #[must_use]
    pub fn velocities(&self) -> &[[f64; 2]] {
        &self.velocities
    }

    /// Collisions since the last reset.
    #[must_use]
    pub fn collisions(&self) -> &Collisions {
        &self.collisions
    }

    /// Noisy sonar readings of `robot`, one per sonar angle, into `out` (draws from the
    /// world's generator).
    pub fn sonar(&mut self, robot: usize, out: &mut [f64]) -> Result<(), SimError> {
        self.sonar_exact(robot, out)?;
        let (lo, hi) = (self.config.sonar_min_range, self.config.sonar_max_range);
        let dropout = self.config.noise.sonar_dropout;
        for v in out.iter_mut() {
            if dropout > 0.0 && self.rng.random::<f64>() < dropout {
                *v = hi;
                continue;
            }
            if let Some(d) = &self.sonar_noise {
                *v = (*v + d.sample(&mut self.rng)).clamp(lo, hi);
            }
        }
        Ok(())
    }

    /// Sonar readings of `robot` without noise, one per sonar angle, into `out`.
    pub fn sonar_exact(&self, robot: usize, out: &mut [f64]) -> Result<(), SimError> {
        let c = &self.config;
        if robot >= c.agents {
            return Err(EvalError::OutOfRange {
                what: "robot",
                index: robot,
                len: c.agents,
            }
            .into());
        }
        if !self.placed {
            return Err(
                ConfigError::invalid("poses", "reset the world before reading sonars").into(),
            );
        }
        check_len("sonar readings", c.sonar_angles_deg.len(), out.len())?;
        let pose = self.poses[robot];
        let filter = QueryFilter::default().exclude_rigid_body(self.engine.robots[robot].body);
        let query = self.engine.world.query_pipeline_with_filter(filter);
        let cone = c.sonar_cone_deg.to_radians();
        let rays = c.rays_per_sonar;
        let max = c.sonar_max_range;
        for (o, a) in out.iter_mut().zip(&c.sonar_angles_deg) {
            let mut best = max;
            for j in 0..rays {
                let off = if rays == 1 {
                    0.0
                } else {
                    -0.5 * cone + cone * j as f64 / (rays - 1) as f64
                };
                let (s, co) = (pose[2] + a.to_radians() + off).sin_cos();
                let origin = v2(pose[0] + c.radius * co, pose[1] + c.radius * s);
                let ray = Ray::new(origin, v2(co, s));
                if let Some((_, toi)) = query.cast_ray(&ray, max as f32, true) {
                    best = best.min(f64::from(toi));
                }
            }
            *o = best.clamp(c.sonar_min_range, max);
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use std::f64::consts::PI;

    use super::*;
    use crate::model::arena::{Arena, Obstacle};

    fn one_robot(arena: Arena) -> KheperaConfig {
        KheperaConfig {
            agents: 1,
            arena,
            ..KheperaConfig::default()
        }
    }

    /// Distance along `dir` from `origin` to the circle `(c, r)`, if hit.
    fn ray_circle(origin: [f64; 2], dir: [f64; 2], c: [f64; 2], r: f64) -> Option<f64> {
        let m = [origin[0] - c[0], origin[1] - c[1]];
        let b = m[0] * dir[0] + m[1] * dir[1];
        let cc = m[0] * m[0] + m[1] * m[1] - r * r;
        let disc = b * b - cc;
        (disc >= 0.0 && -b - disc.sqrt() >= 0.0).then(|| -b - disc.sqrt())
    }

    /// The reference reading: minimum over the cone rays of the arena's and the other robots'
    /// exact distances.
    fn reference_sonar(c: &KheperaConfig, poses: &[[f64; 3]], robot: usize) -> Vec<f64> {
        let p = poses[robot];
        let cone = c.sonar_cone_deg.to_radians();
        c.sonar_angles_deg
            .iter()
            .map(|a| {
                let mut best = c.sonar_max_range;
                for j in 0..c.rays_per_sonar {
                    let off = if c.rays_per_sonar == 1 {
                        0.0
                    } else {
                        -0.5 * cone + cone * j as f64 / (c.rays_per_sonar - 1) as f64
                    };
                    let (s, co) = (p[2] + a.to_radians() + off).sin_cos();
                    let o = [p[0] + c.radius * co, p[1] + c.radius * s];
                    if let Some(t) = c.arena.ray_distance(o, [co, s], c.sonar_max_range) {
                        best = best.min(t);
                    }
                    for (k, q) in poses.iter().enumerate() {
                        if k != robot
                            && let Some(t) = ray_circle(o, [co, s], [q[0], q[1]], c.radius)
                        {
                            best = best.min(t);
                        }
                    }
                }
                best.clamp(c.sonar_min_range, c.sonar_max_range)
            })
            .collect()
    }

    #[test]
    fn sonar_readings_match_hand_computed_distances() {
        let c = one_robot(Arena::default());
        let mut w = KheperaWorld::new(&c, 1).unwrap();
        let mut out = [0.0; 5];
        // In the middle: nothing within 2 m.
        w.reset(&[[0.0, 0.0, 0.0]]).unwrap();
        w.sonar_exact(0, &mut out).unwrap();
        assert_eq!(out, [2.0; 5]);
        // Facing the wall at x = 6 from x = 5: the centre ray reads 6 - 5 - 0.07.
        w.reset(&[[5.0, 0.0, 0.0]]).unwrap();
        w.sonar_exact(0, &mut out).unwrap();
        assert!((out[2] - 0.93).abs() < 1e-4, "{out:?}");
        // The side sonars look along the wall: max range.
        assert_eq!([out[0], out[4]], [2.0, 2.0]);
        // The 45-degree sonars: their cone's nearest ray, by hand.
        let cone = 10f64.to_radians();
        let a = 45f64.to_radians() - cone;
        let by_hand = (1.0 - 0.07 * a.cos()) / a.cos();
        assert!((out[3] - by_hand).abs() < 1e-4, "{out:?} vs {by_hand}");
        assert!((out[1] - by_hand).abs() < 1e-4, "{out:?} vs {by_hand}");

        // A rotated box and a second robot.
        let arena = Arena {
            obstacles: vec![
                Obstacle::Box {
                    center: [1.0, 1.0],
                    half_extents: [0.3, 0.1],
                    angle_deg: 30.0,
                },
                Obstacle::Disc {
                    center: [-1.2, 0.3],
                    radius: 0.2,
                },
            ],
            ..Arena::default()
        };
        let c = KheperaConfig {
            agents: 2,
            arena,
            ..KheperaConfig::default()
        };
        let mut w = KheperaWorld::new(&c, 1).unwrap();
        let poses = [[0.3, 0.2, 0.4], [0.9, -0.3, 2.0]];
        w.reset(&poses).unwrap();
        for r in 0..2 {
            w.sonar_exact(r, &mut out).unwrap();
            let expect = reference_sonar(&c, &poses, r);
            for (a, b) in out.iter().zip(&expect) {
                assert!((a - b).abs() < 1e-4, "robot {r}: {out:?} vs {expect:?}");
            }
            assert!(
                expect.iter().any(|&v| v < 1.9),
                "the scene is seen: {expect:?}"
            );
        }

        // By hand, one ray per sonar: a box 0.9 m ahead, the other robot 1 m to the left.
        let c = KheperaConfig {
            agents: 2,
            rays_per_sonar: 1,
            arena: Arena {
                obstacles: vec![Obstacle::Box {
                    center: [1.0, 0.0],
                    half_extents: [0.1, 0.5],
                    angle_deg: 0.0,
                }],
                ..Arena::default()
            },
            ..KheperaConfig::default()
        };
        let mut w = KheperaWorld::new(&c, 1).unwrap();
        w.reset(&[[0.0, 0.0, 0.0], [0.0, 1.0, 0.0]]).unwrap();
        w.sonar_exact(0, &mut out).unwrap();
        // Right: nothing within 2 m; diagonals pass beside the box and the robot; front: the
        // box face at x = 0.9 from the rim at 0.07; left: the other rim at 1 - 0.07.
        let expect = [2.0, 2.0, 0.9 - 0.07, 2.0, 1.0 - 0.07 - 0.07];
        for (a, b) in out.iter().zip(&expect) {
            assert!((a - b).abs() < 1e-5, "{out:?} vs {expect:?}");
        }
    }

    #[test]
    fn sonars_never_see_their_own_robot() {
        let big = Arena {
            x: [-50.0, 50.0],
            y: [-50.0, 50.0],
            obstacles: vec![],
        };
        let c = KheperaConfig {
            rays_per_sonar: 9,
            sonar_cone_deg: 170.0,
            sonar_min_range: 0.01,
            ..one_robot(big.clone())
        };
        let mut w = KheperaWorld::new(&c, 1).unwrap();
        let mut out = [0.0; 5];
        for h in [0.0, 1.0, -2.5, PI] {
            w.reset(&[[0.3, -0.7, h]]).unwrap();
            w.sonar_exact(0, &mut out).unwrap();
            assert_eq!(out, [2.0; 5], "heading {h}");
        }
        // Two robots side by side: each reads the other at the rim-to-rim gap.
        let c = KheperaConfig {
            agents: 2,
            rays_per_sonar: 1,
            sonar_min_range: 0.01,
            arena: big,
            ..KheperaConfig::default()
        };
        let mut w = KheperaWorld::new(&c, 1).unwrap();
        w.reset(&[[0.0, 0.0, 0.0], [0.5, 0.0, PI]]).unwrap();
        for r in 0..2 {
            w.sonar_exact(r, &mut out).unwrap();
            assert!((out[2] - (0.5 - 0.14)).abs() < 1e-5, "{r}: {out:?}");
            assert_eq!([out[0], out[1], out[3], out[4]], [2.0; 4]);
        }
    }

    #[test]
    fn khepera_open_space_motion_is_drive() {
        let c = KheperaConfig::default();
        let mut w = KheperaWorld::new(&c, 3).unwrap();
        let mut poses = [[-4.0, 5.0, 0.3], [2.0, -1.0, -2.9]];
        w.reset(&poses).unwrap();
        let script = [
            [0.2, 0.2],
            [0.03, -0.03],
            [0.1, 0.25],
            [-0.8, 0.8],
            [0.0, 0.0],
        ];
        for k in 0..40 {
            let wheels = [script[k % 5], script[(k + 2) % 5]];
            let contacts = w.step(&wheels).unwrap();
            assert!(contacts.is_empty());
            for (p, wh) in poses.iter_mut().zip(&wheels) {
                *p = khepera::drive(*p, *wh, c.wheel_base, c.sample_time);
            }
            for (a, b) in w.poses().iter().zip(&poses) {
                assert!(
                    (a[0] - b[0]).abs() < 1e-6 && (a[1] - b[1]).abs() < 1e-6,
                    "{k}"
                );
                assert!(
                    khepera::wrap_heading(a[2] - b[2]).abs() < 1e-6,
                    "{k}: {a:?} {b:?}"
                );
            }
        }
        let v = w.velocities()[0];
        assert!(v[0].is_finite() && v[1].is_finite());
    }

    #[test]
    fn khepera_stops_at_walls_and_obstacles() {
        let arena = Arena {
            obstacles: vec![Obstacle::Box {
                center: [0.0, 2.0],
                half_extents: [1.0, 0.2],
                angle_deg: 0.0,
            }],
            ..Arena::default()
        };
        let c = KheperaConfig {
            agents: 2,
            arena,
            ..KheperaConfig::default()
        };
        let mut w = KheperaWorld::new(&c, 0).unwrap();
        // Robot 0 drives at the right wall, robot 1 up into the box.
        w.reset(&[[5.5, 0.0, 0.0], [0.0, 1.0, PI / 2.0]]).unwrap();
        let full = [[0.8, 0.8], [0.8, 0.8]];
        for _ in 0..20 {
            w.step(&full).unwrap();
            let p = w.poses();
            assert!(p[0][0] <= 6.0 - 0.07 + 1e-3, "{p:?}");
            assert!(p[1][1] <= 1.8 - 0.07 + 1e-3, "{p:?}");
        }
        let p = w.poses();
        assert!(p[0][0] > 6.0 - 0.07 - 2e-3, "{p:?}");
        assert!(p[1][1] > 1.8 - 0.07 - 2e-3, "{p:?}");
        let col = w.collisions();
        assert_eq!(col.robot_wall, 1, "{col:?}");
        assert_eq!(col.robot_obstacle, 1, "{col:?}");
        assert_eq!(col.per_agent, vec![1, 1]);
        // Pressed against the wall, the robot barely moves.
        let v = w.velocities()[0];
        assert!(v[0].abs() < 1e-2, "{v:?}");

        // Head on into each other.
        let c = KheperaConfig::default();
        let mut w = KheperaWorld::new(&c, 0).unwrap();
        w.reset(&[[-0.5, 0.0, 0.0], [0.5, 0.0, PI]]).unwrap();
        for _ in 0..20 {
            w.step(&full).unwrap();
            let p = w.poses();
            let gap = (p[0][0] - p[1][0]).hypot(p[0][1] - p[1][1]) - 0.14;
            assert!(gap > -3e-3, "{gap}");
        }
        assert_eq!(w.collisions().robot_robot, 1);
        assert_eq!(w.collisions().total, 1);
    }

    #[test]
    fn khepera_noise_is_seeded() {
        let c = KheperaConfig {
            noise: khepera::NoiseConfig {
                sonar_std: 0.05,
                sonar_dropout: 0.1,
                wheel_std: 0.1,
            },
            ..KheperaConfig::default()
        };
        let run = |seed: u64| {
            let mut w = KheperaWorld::new(&c, seed).unwrap();
            w.reset(&[[-4.0, 5.0, 0.0], [5.0, 3.0, 0.0]]).unwrap();
            let mut trace = Vec::new();
            let mut s = [0.0; 5];
            for k in 0..30 {
                let a = if k % 3 == 0 {
                    [0.03, -0.03]
                } else {
                    [0.2, 0.2]
                };
                w.step(&[a, a]).unwrap();
                for r in 0..2 {
                    trace.extend_from_slice(&w.poses()[r]);
                    w.sonar(r, &mut s).unwrap();
                    trace.extend_from_slice(&s);
                }
            }
            trace
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7), run(8));
    }

    #[test]
    fn khepera_rejects_bad_input() {
        let c = KheperaConfig::default();
        let mut w = KheperaWorld::new(&c, 0).unwrap();
        let e = w.reset(&[[5.95, 0.0, 0.0], [0.0, 0.0, 0.0]]).unwrap_err();
        assert!(e.to_string().contains("robot 0"), "{e}");
        let e = w.reset(&[[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]).unwrap_err();
        assert!(e.to_string().contains("robot 1"), "{e}");
        assert!(w.reset(&[[0.0, 0.0, 0.0]]).is_err());
        assert!(w.step(&[[0.0; 2]; 2]).is_err(), "step before reset");
        w.reset(&[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]).unwrap();
        assert!(w.step(&[[0.0, f64::INFINITY], [0.0; 2]]).is_err());
        let mut out = [0.0; 5];
        assert!(w.sonar(2, &mut out).is_err());
        assert!(w.sonar(0, &mut out[..3]).is_err());
    }
}
