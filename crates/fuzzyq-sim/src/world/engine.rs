//! The rapier world both plants share: the arena's colliders, one disc per body, imposed
//! motion per substep and the touch state of every disc (see the [module docs](super)).

use fuzzyq_core::EvalError;
use fuzzyq_core::error::check_len;
use rapier2d::math::{Rotation, Vector};
use rapier2d::prelude::{
    ColliderBuilder, ColliderHandle, PhysicsWorld, RigidBodyBuilder, RigidBodyHandle,
};

use super::contacts::{ContactStart, Partner, WallSide};
use crate::error::SimError;
use crate::model::arena::Obstacle;
use crate::model::khepera::MAX_ROBOTS;

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
pub(super) const SOFT_CCD: f32 = 100.0;

/// Length of the step that applies teleports (s).
pub(super) const REFRESH_DT: f32 = 1e-6;

/// A velocity change below this (m/s or rad/s, relative to `1 + |v|`) is `f32` rounding.
pub(super) const VEL_TOL: f64 = 1e-5;

/// A displacement error below this (m) is `f32` rounding.
pub(super) const POS_TOL: f64 = 2e-5;

/// The motion imposed on one disc over a substep.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Motion {
    pub(super) pos: [f64; 2],
    pub(super) angle: f64,
    pub(super) linvel: [f64; 2],
    pub(super) angvel: f64,
}

/// What rapier made of a [`Motion`].
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct Outcome {
    /// Whether the translation or the linear velocity was altered.
    pub(super) linear: bool,
    /// Whether the angular velocity was altered.
    pub(super) angular: bool,
    pub(super) pos: [f64; 2],
    pub(super) angle: f64,
    /// Linear velocity after the step minus the one given.
    pub(super) dlinvel: [f64; 2],
}

pub(super) struct RobotBody {
    pub(super) body: RigidBodyHandle,
    pub(super) collider: ColliderHandle,
}

/// The rapier world shared by both plants: static arena colliders and one dynamic disc per
/// robot, with the touch state of every robot against every collider.
pub(super) struct Engine {
    pub(super) world: PhysicsWorld,
    /// Every collider and what it is (robot `i` is in slot `robot_slot0 + i`).
    pub(super) slots: Vec<(ColliderHandle, Partner)>,
    pub(super) robot_slot0: usize,
    pub(super) robots: Vec<RobotBody>,
    /// `touching[r][slot]`.
    pub(super) touching: Vec<Vec<bool>>,
}

pub(super) fn v2(x: f64, y: f64) -> Vector {
    Vector::new(x as f32, y as f32)
}

impl Engine {
    /// `walls = [x_lo, x_hi, y_lo, y_hi]` are the walls' inner faces.
    pub(super) fn new(
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
    pub(super) fn refresh(&mut self) {
        self.world.integration_parameters.dt = REFRESH_DT;
        self.world.step();
    }

    /// Places every robot at rest at `poses` (`[x, y, heading]`) and takes the touches there as
    /// the current state (no collisions).
    pub(super) fn place(&mut self, poses: &[[f64; 3]]) {
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
    pub(super) fn distance(&self, r: usize, s: usize) -> f64 {
        let a = &self.world.colliders[self.robots[r].collider];
        let b = &self.world.colliders[self.slots[s].0];
        rapier2d::parry::query::distance(a.position(), a.shape(), b.position(), b.shape())
            .map_or(f64::INFINITY, |d| f64::from(d.distance))
    }

    /// Updates the touch state after a substep, recording rising edges in `starts`.
    pub(super) fn update_touching(&mut self, mut starts: Option<&mut Vec<ContactStart>>) {
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
    pub(super) fn substep(
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
pub(super) fn contact_velocity(v1: [f64; 2], dv: [f64; 2]) -> [f64; 2] {
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

pub(super) fn check_slice(what: &'static str, expected: usize, v: &[f64]) -> Result<(), SimError> {
    check_len(what, expected, v.len())?;
    if let Some(index) = v.iter().position(|x| !x.is_finite()) {
        return Err(EvalError::NotFinite { what, index }.into());
    }
    Ok(())
}
