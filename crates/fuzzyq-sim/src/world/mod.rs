//! Physics plants: the point masses and the Khepera robots as rigid discs in a walled arena,
//! simulated with [rapier2d](https://rapier.rs), so that a policy learned on a model can be run
//! where bodies really collide.
//!
//! # Exact motion, rapier for contacts only
//! A plant must agree with the model a policy was trained on wherever nothing touches:
//! otherwise a difference between model and plant could not be told apart from the effect of
//! the contacts. Rapier's own integrator does not give the models' motion: it integrates
//! linear damping as `v / (1 + dt c)` and positions with the (undamped) solver substep
//! velocities, so `m s'' = -eta s' + u` would drift from the exact zero-order-hold solution by
//! `O(dt)`; a differential-drive robot follows circular arcs, not the straight chords of a
//! velocity step; and rapier advances rotations to first order (by `atan(w dt)` per solver
//! iteration). So rapier only resolves contacts, and the motion is imposed:
//!
//! - every control step of sample time `T` is split into `K` substeps (`substeps`, default 8)
//!   of `h = T / K`;
//! - at each substep the model's exact successor over `h` is computed in `f64` (the point
//!   mass's zero-order hold under the held force, [`PointMass::step_f64`] with sample time
//!   `h`; the robot's arc, [`khepera::drive`]), the body is placed at the current state (in
//!   `f32`) and given the velocity that carries it there in `h` (`(s' - s) / h`, and for a
//!   robot the wrapped heading change over `h`), and rapier steps by `h` (no gravity, no
//!   damping, friction and restitution 0, so bodies slide along what they touch);
//! - a body whose motion rapier did not alter (its velocity and displacement are what it was
//!   given, up to `f32` rounding) takes the exact successor, in `f64`: in open space the plant
//!   equals the model to rounding, composition over substeps included. A body a contact did
//!   alter takes rapier's position; a point mass's velocity becomes the exact successor's plus
//!   the velocity change of the contact, less any remaining component into the contact
//!   (restitution 0: a disc pushed against a wall rests there); a robot keeps the exact heading
//!   (a frictionless contact with a disc exerts no torque) unless its angular velocity was
//!   changed too.
//!
//! The discs carry rapier's soft CCD (speculative contacts over the whole substep motion), so
//! they cannot tunnel through each other or the walls at the speeds of these tasks (point
//! masses at 3 m/s: 0.15 m per default substep); a near miss at full speed may be slowed
//! slightly, the price of speculative contacts, which more substeps reduce.
//!
//! # Arena
//! The arena's walls are four thick cuboids just outside its rectangle and every obstacle is a
//! (rotated) cuboid or a ball. For the Khepera robots the rectangle is the walls' inner face,
//! as for [`Arena::ray_distance`]. For the point masses it bounds the discs' *centres*, as the
//! model clamps positions (to `[-6, 6]` in the paper; its start `[-4, -6, ...]` has a centre on
//! that line): the wall cuboids stand `radius` further out.
//!
//! # Contacts
//! A robot (disc) touches another collider when their distance is at most 1 mm, and stops
//! touching it when the distance exceeds 5 mm (the hysteresis keeps a robot sliding along a
//! wall from flickering). A collision is the start of a touch (a rising edge, checked after
//! every substep), counted per robot and per kind of partner: [`StepContacts`] lists those of
//! one control step and [`Collisions`] accumulates them. Touches present at a reset are not
//! collisions.
//!
//! # Sonars
//! Sonar `k` of robot `r` casts `rays_per_sonar` rays spread evenly over
//! `[a_k - cone / 2, a_k + cone / 2]` (one ray at `a_k` for a single ray) from the robot's rim
//! outward against the walls, the obstacles and the other robots (a query filter excludes the
//! robot's own body). The reading is the nearest hit measured from the rim, clamped to
//! `[sonar_min_range, sonar_max_range]`, the maximum when nothing is hit within range; the
//! [`NoiseConfig`](crate::model::khepera::NoiseConfig) of the configuration then applies, drawn from the
//! world's own seeded generator.

use fuzzyq_core::{EvalError, Model, Real};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use rand_pcg::Pcg64Mcg;
use rapier2d::math::{Rotation, Vector};
use rapier2d::prelude::{
    ColliderBuilder, ColliderHandle, PhysicsWorld, QueryFilter, Ray, RigidBodyBuilder,
    RigidBodyHandle,
};
use serde::{Deserialize, Serialize};

use crate::error::{ConfigError, SimError};
use crate::model::EnvModel;
use crate::model::arena::{Arena, Obstacle};
use crate::model::khepera::{self, KheperaConfig, MAX_ROBOTS};
use crate::model::pointmass::{FrictionConfig, PointMass, PointMassConfig};
use crate::run::policy::{Policy, PolicyKind};
use crate::run::rollout::{RolloutMetrics, Trajectory, point_mass_of, rollout_on};

/// Thickness of the wall cuboids (m).
pub const WALL_THICKNESS: f64 = 0.5;

/// Distance at or below which two colliders touch (m).
pub const TOUCH_DISTANCE: f64 = 1e-3;

/// Distance above which a touch ends (m).
pub const RELEASE_DISTANCE: f64 = 5e-3;

/// Mass of a Khepera IV robot (kg).
pub const KHEPERA_MASS: f64 = 0.54;

/// Largest number of substeps per control step.
pub const MAX_SUBSTEPS: usize = 10_000;

/// Soft-CCD reach of the discs (m): a bound on the motion of one substep, large enough never to
/// limit it at these speeds.
const SOFT_CCD: f32 = 100.0;

/// Length of the step that applies teleports (s).
const REFRESH_DT: f32 = 1e-6;

/// A velocity change below this (m/s or rad/s, relative to `1 + |v|`) is `f32` rounding.
const VEL_TOL: f64 = 1e-5;

/// A displacement error below this (m) is `f32` rounding.
const POS_TOL: f64 = 2e-5;

/// One of the four walls.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WallSide {
    /// The wall at the low end of `x`.
    Left,
    /// The wall at the high end of `x`.
    Right,
    /// The wall at the low end of `y`.
    Bottom,
    /// The wall at the high end of `y`.
    Top,
}

/// What a robot touched.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Partner {
    /// A wall.
    Wall(WallSide),
    /// An obstacle, by its index in the arena's list.
    Obstacle(usize),
    /// Another robot (or point mass), by its index.
    Robot(usize),
}

/// The kind of a [`Partner`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ContactKind {
    /// Another robot.
    Robot,
    /// A wall.
    Wall,
    /// An obstacle.
    Obstacle,
}

impl Partner {
    /// The partner's kind.
    #[must_use]
    pub fn kind(&self) -> ContactKind {
        match self {
            Self::Wall(_) => ContactKind::Wall,
            Self::Obstacle(_) => ContactKind::Obstacle,
            Self::Robot(_) => ContactKind::Robot,
        }
    }
}

/// The start of a contact between robot `agent` and `partner`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ContactStart {
    /// The robot (or point mass).
    pub agent: usize,
    /// What it touched.
    pub partner: Partner,
}

/// The contacts that started during one control step.
///
/// A contact between two robots `i` and `j` is listed twice, once for each robot.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct StepContacts {
    /// Every start, in the order found (substep by substep, robot by robot).
    pub starts: Vec<ContactStart>,
}

impl StepContacts {
    /// Whether no contact started.
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.starts.is_empty()
    }

    /// Number of contacts of `kind` that `agent` started.
    #[must_use]
    pub fn count(&self, agent: usize, kind: ContactKind) -> usize {
        self.starts
            .iter()
            .filter(|s| s.agent == agent && s.partner.kind() == kind)
            .count()
    }

    /// Number of contacts `agent` started, of any kind.
    #[must_use]
    pub fn agent_count(&self, agent: usize) -> usize {
        self.starts.iter().filter(|s| s.agent == agent).count()
    }
}

/// Counts of contact starts (collisions) over a run.
///
/// `total = robot_robot + robot_wall + robot_obstacle`: a collision between two robots counts
/// once there, and once for each of the two in `per_agent`.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Collisions {
    /// All collisions.
    pub total: usize,
    /// Collisions each agent took part in.
    pub per_agent: Vec<usize>,
    /// Collisions between two agents.
    pub robot_robot: usize,
    /// Collisions of an agent with a wall.
    pub robot_wall: usize,
    /// Collisions of an agent with an obstacle.
    pub robot_obstacle: usize,
}

impl Collisions {
    /// No collisions yet, for `agents` agents.
    #[must_use]
    pub fn new(agents: usize) -> Self {
        Self {
            per_agent: vec![0; agents],
            ..Self::default()
        }
    }

    /// Adds one control step's contact starts.
    pub fn add(&mut self, step: &StepContacts) {
        for s in &step.starts {
            if let Some(c) = self.per_agent.get_mut(s.agent) {
                *c += 1;
            }
            match s.partner {
                // Listed once per robot: count the pair at its lower index.
                Partner::Robot(other) => {
                    if s.agent < other {
                        self.robot_robot += 1;
                        self.total += 1;
                    }
                }
                Partner::Wall(_) => {
                    self.robot_wall += 1;
                    self.total += 1;
                }
                Partner::Obstacle(_) => {
                    self.robot_obstacle += 1;
                    self.total += 1;
                }
            }
        }
    }
}

/// The motion imposed on one disc over a substep.
#[derive(Clone, Copy, Debug, Default)]
struct Motion {
    pos: [f64; 2],
    angle: f64,
    linvel: [f64; 2],
    angvel: f64,
}

/// What rapier made of a [`Motion`].
#[derive(Clone, Copy, Debug, Default)]
struct Outcome {
    /// Whether the translation or the linear velocity was altered.
    linear: bool,
    /// Whether the angular velocity was altered.
    angular: bool,
    pos: [f64; 2],
    angle: f64,
    /// Linear velocity after the step minus the one given.
    dlinvel: [f64; 2],
}

struct RobotBody {
    body: RigidBodyHandle,
    collider: ColliderHandle,
}

/// The rapier world shared by both plants: static arena colliders and one dynamic disc per
/// robot, with the touch state of every robot against every collider.
struct Engine {
    world: PhysicsWorld,
    /// Every collider and what it is (robot `i` is in slot `robot_slot0 + i`).
    slots: Vec<(ColliderHandle, Partner)>,
    robot_slot0: usize,
    robots: Vec<RobotBody>,
    /// `touching[r][slot]`.
    touching: Vec<Vec<bool>>,
}

fn v2(x: f64, y: f64) -> Vector {
    Vector::new(x as f32, y as f32)
}

impl Engine {
    /// `walls = [x_lo, x_hi, y_lo, y_hi]` are the walls' inner faces.
    fn new(
        walls: [f64; 4],
        obstacles: &[Obstacle],
        n: usize,
        radius: f64,
        mass: f64,
        lock_rotations: bool,
    ) -> Self {
        let mut world = PhysicsWorld::new();
        world.gravity = Vector::ZERO;
        world.integration_parameters.contact_recycling = false;
        let material = |b: ColliderBuilder| b.friction(0.0).restitution(0.0);
        let mut slots = Vec::new();
        let [x0, x1, y0, y1] = walls;
        let t = WALL_THICKNESS;
        let (cx, cy) = (0.5 * (x0 + x1), 0.5 * (y0 + y1));
        let (hx, hy) = (0.5 * (x1 - x0) + t, 0.5 * (y1 - y0) + t);
        for (side, center, half) in [
            (WallSide::Left, [x0 - 0.5 * t, cy], [0.5 * t, hy]),
            (WallSide::Right, [x1 + 0.5 * t, cy], [0.5 * t, hy]),
            (WallSide::Bottom, [cx, y0 - 0.5 * t], [hx, 0.5 * t]),
            (WallSide::Top, [cx, y1 + 0.5 * t], [hx, 0.5 * t]),
        ] {
            let c = material(ColliderBuilder::cuboid(half[0] as f32, half[1] as f32))
                .translation(v2(center[0], center[1]));
            let h = world.insert_collider(c, None);
            slots.push((h, Partner::Wall(side)));
        }
        for (i, o) in obstacles.iter().enumerate() {
            let c = match o {
                Obstacle::Box {
                    center,
                    half_extents,
                    angle_deg,
                } => ColliderBuilder::cuboid(half_extents[0] as f32, half_extents[1] as f32)
                    .translation(v2(center[0], center[1]))
                    .rotation(angle_deg.to_radians() as f32),
                Obstacle::Disc { center, radius } => {
                    ColliderBuilder::ball(*radius as f32).translation(v2(center[0], center[1]))
                }
            };
            let h = world.insert_collider(material(c), None);
            slots.push((h, Partner::Obstacle(i)));
        }
        let robot_slot0 = slots.len();
        let mut robots = Vec::with_capacity(n);
        for i in 0..n {
            // Parked apart beyond the right wall until the first reset.
            let park = v2(x1 + t + 1.0 + 4.0 * radius * i as f64, cy);
            let mut b = RigidBodyBuilder::dynamic()
                .translation(park)
                .can_sleep(false)
                .soft_ccd_prediction(SOFT_CCD)
                .allow_fast_rotation(true);
            if lock_rotations {
                b = b.lock_rotations();
            }
            let c = material(ColliderBuilder::ball(radius as f32)).mass(mass as f32);
            let (body, collider) = world.insert(b, c);
            slots.push((collider, Partner::Robot(i)));
            robots.push(RobotBody { body, collider });
        }
        let touching = vec![vec![false; slots.len()]; n];
        let mut engine = Self {
            world,
            slots,
            robot_slot0,
            robots,
            touching,
        };
        engine.refresh();
        engine
    }

    /// Applies teleports to the colliders and the query structures, with the robots at rest.
    ///
    /// A step of (almost) no time: rapier 0.36's zero-length step leaves the scene-query tree
    /// unusable after a dynamic body was moved (rays then miss every collider until the next
    /// real step), so a microsecond passes instead.
    fn refresh(&mut self) {
        self.world.integration_parameters.dt = REFRESH_DT;
        self.world.step();
    }

    /// Places every robot at rest at `poses` (`[x, y, heading]`) and takes the touches there as
    /// the current state (no collisions).
    fn place(&mut self, poses: &[[f64; 3]]) {
        for (r, p) in self.robots.iter().zip(poses) {
            let b = &mut self.world.bodies[r.body];
            b.set_translation(v2(p[0], p[1]), true);
            b.set_rotation(Rotation::new(p[2] as f32), true);
            b.set_linvel(Vector::ZERO, true);
            b.set_angvel(0.0, true);
        }
        self.refresh();
        self.update_touching(None);
    }

    /// Distance between the collider of robot `r` and slot `s` (0 when they overlap).
    fn distance(&self, r: usize, s: usize) -> f64 {
        let a = &self.world.colliders[self.robots[r].collider];
        let b = &self.world.colliders[self.slots[s].0];
        rapier2d::parry::query::distance(a.position(), a.shape(), b.position(), b.shape())
            .map_or(f64::INFINITY, |d| f64::from(d.distance))
    }

    /// Updates the touch state after a substep, recording rising edges in `starts`.
    fn update_touching(&mut self, mut starts: Option<&mut Vec<ContactStart>>) {
        let n = self.robots.len();
        for r in 0..n {
            for s in 0..self.slots.len() {
                let partner = self.slots[s].1;
                if let Partner::Robot(o) = partner {
                    // Each pair once, from its lower index; both sides are updated.
                    if o <= r {
                        continue;
                    }
                }
                let d = self.distance(r, s);
                let was = self.touching[r][s];
                let now = if was {
                    d <= RELEASE_DISTANCE
                } else {
                    d <= TOUCH_DISTANCE
                };
                self.touching[r][s] = now;
                if let Partner::Robot(o) = partner {
                    self.touching[o][self.robot_slot0 + r] = now;
                }
                if now
                    && !was
                    && let Some(out) = starts.as_deref_mut()
                {
                    out.push(ContactStart { agent: r, partner });
                    if let Partner::Robot(o) = partner {
                        out.push(ContactStart {
                            agent: o,
                            partner: Partner::Robot(r),
                        });
                    }
                }
            }
        }
    }

    /// One substep of length `h`: imposes `motions`, steps rapier, reports what it did.
    fn substep(
        &mut self,
        h: f64,
        motions: &[Motion],
        outcomes: &mut [Outcome],
        starts: &mut Vec<ContactStart>,
    ) {
        let mut given = [(Vector::ZERO, Vector::ZERO, 0.0f32); MAX_ROBOTS];
        for (i, (r, m)) in self.robots.iter().zip(motions).enumerate() {
            let b = &mut self.world.bodies[r.body];
            let pos = v2(m.pos[0], m.pos[1]);
            let lin = v2(m.linvel[0], m.linvel[1]);
            let (angle, ang) = (m.angle as f32, m.angvel as f32);
            b.set_translation(pos, true);
            b.set_rotation(Rotation::new(angle), true);
            b.set_linvel(lin, true);
            b.set_angvel(ang, true);
            // What rapier actually holds (a locked rotation keeps its own).
            given[i] = (b.translation(), b.linvel(), b.angvel());
        }
        self.world.integration_parameters.dt = h as f32;
        self.world.step();
        for (i, (r, out)) in self.robots.iter().zip(outcomes.iter_mut()).enumerate() {
            let b = &self.world.bodies[r.body];
            let (p0, l0, w0) = given[i];
            let (p, l, a, w) = (
                b.translation(),
                b.linvel(),
                b.rotation().angle(),
                b.angvel(),
            );
            let dl = [f64::from(l.x - l0.x), f64::from(l.y - l0.y)];
            let speed = f64::from(l0.length());
            let hf = f64::from(h as f32);
            let free = [
                f64::from(p0.x) + f64::from(l0.x) * hf,
                f64::from(p0.y) + f64::from(l0.y) * hf,
            ];
            let dp = (f64::from(p.x) - free[0]).hypot(f64::from(p.y) - free[1]);
            *out = Outcome {
                linear: dl[0].hypot(dl[1]) > VEL_TOL * (1.0 + speed) || dp > POS_TOL,
                // Rapier integrates rotations to first order (the angle advances by
                // `atan(w dt)` per solver substep): only a change of the angular velocity
                // reveals a contact.
                angular: f64::from((w - w0).abs()) > VEL_TOL * (1.0 + f64::from(w0.abs())),
                pos: [f64::from(p.x), f64::from(p.y)],
                angle: f64::from(a),
                dlinvel: dl,
            };
        }
        self.update_touching(Some(starts));
    }
}

/// Velocity after a contact: the exact successor's `v1` plus the contact's velocity change
/// `dv`, without a component into the contact. The contact acts along `dv`; rapier stops the
/// *mean* velocity of the substep, and when the force keeps pushing into a wall `v1` exceeds that
/// mean, so `v1 + dv` would still point into the wall: that component is removed (restitution
/// 0).
fn contact_velocity(v1: [f64; 2], dv: [f64; 2]) -> [f64; 2] {
    let mut v = [v1[0] + dv[0], v1[1] + dv[1]];
    let norm = dv[0].hypot(dv[1]);
    if norm > 0.0 {
        let n = [dv[0] / norm, dv[1] / norm];
        let vn = v[0] * n[0] + v[1] * n[1];
        if vn < 0.0 {
            v[0] -= vn * n[0];
            v[1] -= vn * n[1];
        }
    }
    v
}

fn check_slice(what: &'static str, expected: usize, v: &[f64]) -> Result<(), SimError> {
    if v.len() != expected {
        return Err(EvalError::Length {
            what,
            expected,
            found: v.len(),
        }
        .into());
    }
    if let Some(index) = v.iter().position(|x| !x.is_finite()) {
        return Err(EvalError::NotFinite { what, index }.into());
    }
    Ok(())
}

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
    /// The arena; its rectangle bounds the discs' centres (see the [module docs](self)).
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
        if !(self.radius > 0.0 && self.radius.is_finite()) {
            return Err(ConfigError::invalid(
                "plant.radius",
                format!("must be a positive number, got {}", self.radius),
            ));
        }
        if !(1..=MAX_SUBSTEPS).contains(&self.substeps) {
            return Err(ConfigError::invalid(
                "plant.substeps",
                format!(
                    "must be between 1 and {MAX_SUBSTEPS}, got {}",
                    self.substeps
                ),
            ));
        }
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

/// The point masses of [`PointMass`] as colliding discs (see the [module docs](self)).
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
            if s[0] < a.x[0] || s[0] > a.x[1] || s[1] < a.y[0] || s[1] > a.y[1] {
                return Err(ConfigError::invalid(
                    "x0",
                    format!(
                        "agent {i} at ({}, {}) is outside the arena x = {:?}, y = {:?}",
                        s[0], s[1], a.x, a.y
                    ),
                )
                .into());
            }
            if self.physical.disc_collides(s, r) {
                return Err(ConfigError::invalid(
                    "x0",
                    format!("agent {i} at ({}, {}) overlaps an obstacle", s[0], s[1]),
                )
                .into());
            }
            for k in 2..4 {
                let v = x[4 * i + k];
                if v.abs() > self.velocity_limit {
                    return Err(ConfigError::invalid(
                        "x0",
                        format!(
                            "agent {i} velocity {v} exceeds the limit {}",
                            self.velocity_limit
                        ),
                    )
                    .into());
                }
            }
            for j in 0..i {
                let d = (s[0] - x[4 * j]).hypot(s[1] - x[4 * j + 1]);
                if d < 2.0 * r {
                    return Err(ConfigError::invalid(
                        "x0",
                        format!("agents {j} and {i} overlap (centres {d} m apart, radius {r} m)"),
                    )
                    .into());
                }
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

/// Runs `policy` for `steps` steps from `x0` on the point-mass plant: as
/// [`rollout`](crate::run::rollout::rollout), with the discs colliding; also returns the
/// collisions.
pub fn rollout_plant<T: Real>(
    policy: &Policy<T>,
    x0: &[f64],
    steps: usize,
    kind: PolicyKind,
    plant: &PointMassPlantConfig,
) -> Result<(Trajectory, RolloutMetrics, Collisions), SimError>
where
    EnvModel: Model<T>,
{
    let mut world = PointMassPlant::new(point_mass_of(policy)?, plant)?;
    let mut placed = false;
    let (trajectory, metrics) = rollout_on(policy, x0, steps, kind, |x, u, next| {
        if !placed {
            world.reset(x)?;
            placed = true;
        }
        world.step(u)?;
        next.copy_from_slice(world.state());
        Ok(())
    })?;
    Ok((trajectory, metrics, world.collisions.clone()))
}

// ---------------------------------------------------------------------------------------------
// Khepera robots
// ---------------------------------------------------------------------------------------------

/// Khepera IV robots as colliding discs with sonars (see the [module docs](self)).
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
        if !(1..=MAX_SUBSTEPS).contains(&substeps) {
            return Err(ConfigError::invalid(
                "plant.substeps",
                format!("must be between 1 and {MAX_SUBSTEPS}, got {substeps}"),
            )
            .into());
        }
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
        if poses.len() != n {
            return Err(EvalError::Length {
                what: "poses",
                expected: n,
                found: poses.len(),
            }
            .into());
        }
        let r = self.config.radius;
        for (i, p) in poses.iter().enumerate() {
            if let Some(index) = p.iter().position(|v| !v.is_finite()) {
                return Err(EvalError::NotFinite {
                    what: "poses",
                    index: 3 * i + index,
                }
                .into());
            }
            if self.config.arena.disc_collides([p[0], p[1]], r) {
                return Err(ConfigError::invalid(
                    format!("poses[{i}]"),
                    format!(
                        "robot {i} at ({}, {}) overlaps a wall or an obstacle",
                        p[0], p[1]
                    ),
                )
                .into());
            }
            for (j, q) in poses[..i].iter().enumerate() {
                if khepera::robots_overlap([p[0], p[1]], [q[0], q[1]], r) {
                    return Err(ConfigError::invalid(
                        format!("poses[{i}]"),
                        format!("robot {i} overlaps robot {j}"),
                    )
                    .into());
                }
            }
        }
        self.poses = poses
            .iter()
            .map(|p| [p[0], p[1], khepera::wrap_angle(p[2])])
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
        if wheels.len() != n {
            return Err(EvalError::Length {
                what: "wheels",
                expected: n,
                found: wheels.len(),
            }
            .into());
        }
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
                    angvel: khepera::wrap_angle(q[2] - p[2]) / h,
                };
            }
            self.engine
                .substep(h, &motions[..n], &mut outcomes[..n], &mut contacts.starts);
            for i in 0..n {
                let (o, q) = (&outcomes[i], targets[i]);
                let xy = if o.linear { o.pos } else { [q[0], q[1]] };
                let heading = if o.angular {
                    khepera::wrap_angle(o.angle)
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
        if out.len() != c.sonar_angles_deg.len() {
            return Err(EvalError::Length {
                what: "sonar readings",
                expected: c.sonar_angles_deg.len(),
                found: out.len(),
            }
            .into());
        }
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
    use crate::run::rollout::PAPER_X0;

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

    #[test]
    fn rollout_plant_equals_rollout_without_contacts() {
        use crate::io::config::{EnvConfig, GridConfig, TrainConfig};
        use crate::run::policy::AnyPolicy;

        fn both<T: Real>(p: &Policy<T>)
        where
            EnvModel: Model<T>,
        {
            let x0 = [-4.0, 3.0, 0.0, 0.0];
            let (a, ma) = crate::run::rollout::rollout(p, &x0, 40, PolicyKind::Greedy).unwrap();
            let (b, mb, col) = rollout_plant(
                p,
                &x0,
                40,
                PolicyKind::Greedy,
                &PointMassPlantConfig::default(),
            )
            .unwrap();
            assert_eq!(col.total, 0);
            assert_eq!(a.actions, b.actions);
            for (x, y) in a.states.iter().zip(&b.states) {
                for (p, q) in x.iter().zip(y) {
                    assert!((p - q).abs() < 1e-9, "{x:?} vs {y:?}");
                }
            }
            assert_eq!(ma.reach_step, mb.reach_step);
            assert!((ma.discounted_return - mb.discounted_return).abs() < 1e-12);
        }

        let mut config = TrainConfig::default();
        if let EnvConfig::Pointmass(p) = &mut config.env {
            p.agents = 1;
        }
        let (pos, vel) = (vec![-6.0, -1.0, 0.0, 1.0, 6.0], vec![-3.0, 0.0, 3.0]);
        config.grid = GridConfig::explicit(vec![pos.clone(), pos, vel.clone(), vel]);
        let artifact =
            crate::train::train(&config, |_| std::ops::ControlFlow::Continue(())).unwrap();
        match AnyPolicy::from_artifact(artifact).unwrap() {
            AnyPolicy::F32(p) => both(&p),
            AnyPolicy::F64(p) => both(&p),
        }
    }

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
                    khepera::wrap_angle(a[2] - b[2]).abs() < 1e-6,
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
