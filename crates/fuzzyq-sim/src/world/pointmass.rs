//! The point masses as colliding discs (see the [module docs](super)).

use serde::{Deserialize, Serialize};

use super::contacts::{Collisions, StepContacts};
use super::engine::*;
use crate::error::{ConfigError, SimError, positive, require, single_precision};
use crate::model::arena::Arena;
use crate::model::khepera::MAX_ROBOTS;
use crate::model::pointmass::{FrictionConfig, PointMass, PointMassConfig};

// ---------------------------------------------------------------------------------------------
// Point masses
// ---------------------------------------------------------------------------------------------

/// Parameters of the point-mass plant.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct PointMassPlantConfig {
    /// Radius of each disc (m).
    pub radius: f64,
    /// Substeps per sample time.
    pub substeps: usize,
    /// The arena; its rectangle bounds the discs' centres (see the [module docs](crate::world)).
    pub arena: Arena,
}

impl Default for PointMassPlantConfig {
    /// Discs of 5 cm, 8 substeps, the paper's open arena (centres within +-6 m).
    fn default() -> Self {
        Self {
            radius: 0.05,
            substeps: 8,
            arena: Arena::default(),
        }
    }
}

impl PointMassPlantConfig {
    /// Checks every field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive("plant.radius", self.radius)?;
        // The physics engine runs in single precision: a radius beyond it would be infinite.
        single_precision("plant.radius", &[self.radius])?;
        require!(
            (1..=MAX_SUBSTEPS).contains(&self.substeps),
            "plant.substeps",
            format!(
                "must be between 1 and {MAX_SUBSTEPS}, got {}",
                self.substeps
            ),
        );
        self.arena.validate()?;
        Ok(())
    }

    /// The arena with its walls where the disc colliders meet them: the rectangle grown by
    /// the radius.
    fn physical_arena(&self) -> Arena {
        let r = self.radius;
        Arena {
            x: [self.arena.x[0] - r, self.arena.x[1] + r],
            y: [self.arena.y[0] - r, self.arena.y[1] + r],
            obstacles: self.arena.obstacles.clone(),
        }
    }
}

/// The point masses of [`PointMass`] as colliding discs (see the [module docs](crate::world)).
pub struct PointMassPlant {
    config: PointMassPlantConfig,
    physical: Arena,
    agents: usize,
    sample_time: f64,
    velocity_limit: f64,
    /// The model over one substep, without clamping.
    sub: PointMass,
    engine: Engine,
    x: Vec<f64>,
    next: Vec<f64>,
    placed: bool,
    collisions: Collisions,
}

impl std::fmt::Debug for PointMassPlant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PointMassPlant")
            .field("config", &self.config)
            .field("state", &self.x)
            .field("collisions", &self.collisions)
            .finish_non_exhaustive()
    }
}

impl PointMassPlant {
    /// Builds the plant for `model`'s agents (mass, friction, sample time, velocity limit).
    ///
    /// The discs are parked outside the arena until [`reset`](Self::reset).
    pub fn new(model: &PointMass, config: &PointMassPlantConfig) -> Result<Self, SimError> {
        config.validate()?;
        let mc = model.config();
        if !model.has_constant_friction() && matches!(mc.friction, FrictionConfig::Constant { .. })
        {
            return Err(ConfigError::invalid(
                "plant",
                "a model built with a friction function cannot be resampled; build it from a \
                 config",
            )
            .into());
        }
        let k = config.substeps;
        let h = mc.sample_time / k as f64;
        let sub = PointMass::new(PointMassConfig {
            sample_time: h,
            position_limit: 1e9,
            velocity_limit: 1e9,
            rk4_substeps: mc.rk4_substeps.div_ceil(k).max(1),
            ..mc.clone()
        })?;
        let physical = config.physical_arena();
        let n = mc.agents;
        let engine = Engine::new(
            [physical.x[0], physical.x[1], physical.y[0], physical.y[1]],
            &physical.obstacles,
            n,
            config.radius,
            mc.mass,
            true,
        );
        let mut x = vec![0.0; 4 * n];
        for i in 0..n {
            let p = engine.world.bodies[engine.robots[i].body].translation();
            x[4 * i] = f64::from(p.x);
            x[4 * i + 1] = f64::from(p.y);
        }
        Ok(Self {
            config: config.clone(),
            physical,
            agents: n,
            sample_time: mc.sample_time,
            velocity_limit: mc.velocity_limit,
            sub,
            engine,
            next: x.clone(),
            x,
            placed: false,
            collisions: Collisions::new(n),
        })
    }

    /// The plant's parameters.
    #[must_use]
    pub fn config(&self) -> &PointMassPlantConfig {
        &self.config
    }

    /// Places the discs at state `x = [s_1x, s_1y, v_1x, v_1y, ...]` and clears the collision
    /// counts. Fails (naming `x0`) if a centre is outside the arena, a velocity exceeds the
    /// limit, or a disc overlaps an obstacle or another disc (touching is allowed).
    pub fn reset(&mut self, x: &[f64]) -> Result<(), SimError> {
        let n = self.agents;
        check_slice("x0", 4 * n, x)?;
        let (r, a) = (self.config.radius, &self.config.arena);
        for i in 0..n {
            let s = [x[4 * i], x[4 * i + 1]];
            require!(
                !(s[0] < a.x[0] || s[0] > a.x[1] || s[1] < a.y[0] || s[1] > a.y[1]),
                "x0",
                format!(
                    "agent {i} at ({}, {}) is outside the arena x = {:?}, y = {:?}",
                    s[0], s[1], a.x, a.y
                ),
            );
            require!(
                !self.physical.disc_collides(s, r),
                "x0",
                format!("agent {i} at ({}, {}) overlaps an obstacle", s[0], s[1]),
            );
            for k in 2..4 {
                let v = x[4 * i + k];
                require!(
                    v.abs() <= self.velocity_limit,
                    "x0",
                    format!(
                        "agent {i} velocity {v} exceeds the limit {}",
                        self.velocity_limit
                    ),
                );
            }
            for j in 0..i {
                let d = (s[0] - x[4 * j]).hypot(s[1] - x[4 * j + 1]);
                require!(
                    d >= 2.0 * r,
                    "x0",
                    format!("agents {j} and {i} overlap (centres {d} m apart, radius {r} m)"),
                );
            }
        }
        self.x.copy_from_slice(x);
        let poses: Vec<[f64; 3]> = (0..n).map(|i| [x[4 * i], x[4 * i + 1], 0.0]).collect();
        self.engine.place(&poses);
        self.collisions = Collisions::new(n);
        self.placed = true;
        Ok(())
    }

    /// Advances one sample time under the joint force vector `u = [u_1x, u_1y, ...]` held
    /// constant; returns the contacts that started. Velocities are clamped to the model's limit
    /// at the end of the step, as the model does.
    pub fn step(&mut self, u: &[f64]) -> Result<StepContacts, SimError> {
        let n = self.agents;
        check_slice("action", 2 * n, u)?;
        if !self.placed {
            return Err(ConfigError::invalid("x0", "reset the plant before stepping").into());
        }
        let k = self.config.substeps;
        let h = self.sample_time / k as f64;
        let mut motions = [Motion::default(); MAX_ROBOTS];
        let mut outcomes = [Outcome::default(); MAX_ROBOTS];
        let mut contacts = StepContacts::default();
        for _ in 0..k {
            self.sub.step_f64(&self.x, u, &mut self.next);
            for i in 0..n {
                let (s, s1) = (&self.x[4 * i..4 * i + 2], &self.next[4 * i..4 * i + 2]);
                motions[i] = Motion {
                    pos: [s[0], s[1]],
                    angle: 0.0,
                    linvel: [(s1[0] - s[0]) / h, (s1[1] - s[1]) / h],
                    angvel: 0.0,
                };
            }
            self.engine
                .substep(h, &motions[..n], &mut outcomes[..n], &mut contacts.starts);
            for i in 0..n {
                let o = &outcomes[i];
                if o.linear {
                    let v =
                        contact_velocity([self.next[4 * i + 2], self.next[4 * i + 3]], o.dlinvel);
                    self.x[4 * i] = o.pos[0];
                    self.x[4 * i + 1] = o.pos[1];
                    self.x[4 * i + 2] = v[0];
                    self.x[4 * i + 3] = v[1];
                } else {
                    self.x[4 * i..4 * i + 4].copy_from_slice(&self.next[4 * i..4 * i + 4]);
                }
            }
        }
        let (a, lim) = (&self.config.arena, self.velocity_limit);
        for i in 0..n {
            // Only f32 rounding at a wall can leave the rectangle.
            self.x[4 * i] = self.x[4 * i].clamp(a.x[0], a.x[1]);
            self.x[4 * i + 1] = self.x[4 * i + 1].clamp(a.y[0], a.y[1]);
            self.x[4 * i + 2] = self.x[4 * i + 2].clamp(-lim, lim);
            self.x[4 * i + 3] = self.x[4 * i + 3].clamp(-lim, lim);
        }
        self.collisions.add(&contacts);
        Ok(contacts)
    }

    /// The state `[s_1x, s_1y, v_1x, v_1y, ...]`.
    #[must_use]
    pub fn state(&self) -> &[f64] {
        &self.x
    }

    /// Collisions since the last reset.
    #[must_use]
    pub fn collisions(&self) -> &Collisions {
        &self.collisions
    }
}

#[cfg(test)]
mod tests {

    use super::*;
    use crate::paper::X0 as PAPER_X0;
    use crate::world::ContactKind;

    fn paper_plant() -> (PointMass, PointMassPlant) {
        let model = PointMass::paper();
        let plant = PointMassPlant::new(&model, &PointMassPlantConfig::default()).unwrap();
        (model, plant)
    }

    #[test]
    fn point_masses_match_the_model_in_open_space() {
        let (model, mut plant) = paper_plant();
        plant.reset(&PAPER_X0).unwrap();
        let forces: [[f64; 4]; 3] = [
            [0.2, 0.2, -0.2, -0.2],
            [0.0, 0.2, -0.2, 0.0],
            [0.2, 0.0, 0.0, -0.2],
        ];
        let mut x = PAPER_X0.to_vec();
        let mut next = x.clone();
        for k in 0..30 {
            let u = forces[k % 3];
            model.step_f64(&x, &u, &mut next);
            std::mem::swap(&mut x, &mut next);
            // The scripted run stays clear of the walls and of each other (after the start).
            if k > 0 {
                for i in 0..2 {
                    assert!(
                        x[4 * i].abs() < 5.8 && x[4 * i + 1].abs() < 5.8,
                        "{k}: {x:?}"
                    );
                }
            }
            let c = plant.step(&u).unwrap();
            assert!(c.is_empty(), "{k}: {c:?}");
            for (a, b) in plant.state().iter().zip(&x) {
                assert!(
                    (a - b).abs() < 1e-9,
                    "step {k}: {:?} vs {x:?}",
                    plant.state()
                );
            }
        }
        assert_eq!(plant.collisions().total, 0);
    }

    #[test]
    fn a_point_mass_stays_inside_the_wall() {
        let (_, mut plant) = paper_plant();
        plant
            .reset(&[5.0, 0.0, 3.0, 0.0, -5.0, 0.0, 0.0, 0.0])
            .unwrap();
        let mut contacts = 0;
        for _ in 0..20 {
            let c = plant.step(&[2.0, 0.0, 0.0, 0.0]).unwrap();
            contacts += c.count(0, ContactKind::Wall);
            let x = plant.state();
            // The centre stays within the wall (at 6 + r) minus the radius.
            assert!(x[0] <= 6.0 + 1e-4, "{x:?}");
        }
        let x = plant.state();
        assert!(x[0] > 5.99, "pressed against the wall: {x:?}");
        assert!(x[2].abs() < 0.05, "stopped: {x:?}");
        assert_eq!(contacts, 1);
        let c = plant.collisions();
        assert_eq!((c.total, c.robot_wall, c.per_agent[0]), (1, 1, 1));
    }

    #[test]
    fn point_masses_collide_with_each_other() {
        let (_, mut plant) = paper_plant();
        plant
            .reset(&[-1.0, 0.0, 3.0, 0.0, 1.0, 0.0, -3.0, 0.0])
            .unwrap();
        let mut min_gap = f64::INFINITY;
        for _ in 0..10 {
            plant.step(&[2.0, 0.0, -2.0, 0.0]).unwrap();
            let x = plant.state();
            min_gap = min_gap.min((x[0] - x[4]).hypot(x[1] - x[5]) - 0.1);
        }
        assert!(min_gap > -3e-3, "interpenetration {min_gap}");
        let c = plant.collisions();
        assert_eq!(c.robot_robot, 1, "{c:?}");
        assert_eq!(c.per_agent, vec![1, 1]);
        assert_eq!(c.total, 1);
    }

    #[test]
    fn point_mass_plant_is_deterministic_and_checks_input() {
        let run = || {
            let (_, mut plant) = paper_plant();
            plant
                .reset(&[-1.0, 0.02, 3.0, 0.0, 1.0, 0.0, -3.0, 0.0])
                .unwrap();
            let mut out = Vec::new();
            for k in 0..40 {
                let u = if k % 2 == 0 {
                    [2.0, 0.2, -2.0, 0.0]
                } else {
                    [2.0, -2.0, 0.2, 2.0]
                };
                plant.step(&u).unwrap();
                out.extend_from_slice(plant.state());
            }
            (out, plant.collisions().clone())
        };
        let (a, ca) = run();
        let (b, cb) = run();
        assert_eq!(a, b);
        assert_eq!(ca, cb);
        assert!(ca.total > 0);

        let (_, mut plant) = paper_plant();
        let e = plant.reset(&[0.0, 0.0, 0.0, 0.0, 0.05, 0.0, 0.0, 0.0]);
        assert!(e.unwrap_err().to_string().contains("x0"));
        let e = plant.reset(&[6.5, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]);
        assert!(e.unwrap_err().to_string().contains("x0"));
        assert!(plant.step(&[0.0; 4]).is_err(), "step before reset");
        plant.reset(&PAPER_X0).unwrap();
        assert!(plant.step(&[0.0; 3]).is_err());
        assert!(plant.step(&[0.0, f64::NAN, 0.0, 0.0]).is_err());
    }
}
