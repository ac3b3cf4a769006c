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
//!   mass's zero-order hold under the held force, [`PointMass::step_f64`](crate::model::pointmass::PointMass::step_f64) with sample time
//!   `h`; the robot's arc, [`khepera::drive`](crate::model::khepera::drive)), the body is placed at the current state (in
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
//! as for [`Arena::ray_distance`](crate::model::arena::Arena::ray_distance). For the point masses it bounds the discs' *centres*, as the
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

mod contacts;
mod engine;
mod khepera;
mod pointmass;

pub use contacts::{Collisions, ContactKind, ContactStart, Partner, StepContacts, WallSide};
pub use engine::{KHEPERA_MASS, MAX_SUBSTEPS, RELEASE_DISTANCE, TOUCH_DISTANCE, WALL_THICKNESS};
pub use khepera::KheperaWorld;
pub use pointmass::{PointMassPlant, PointMassPlantConfig};
