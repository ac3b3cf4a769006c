//! The model of any environment a configuration can name, behind one type.
//!
//! [`EnvModel`] dispatches the [`Model`] trait to the point masses or the Khepera robots, so
//! that training, policies and policy files handle every environment alike.

pub mod arena;
pub mod classic;
pub mod khepera;
pub mod pointmass;

use fuzzyq_core::{ActionSet, Block, Model, Tabulated};

use crate::model::classic::arm::Arm;
use crate::model::classic::carhill::CarHill;
use crate::model::classic::dcmotor::DcMotor;
use crate::model::classic::pendulum::Pendulum;
use crate::model::khepera::KheperaModel;
use crate::model::pointmass::PointMass;

/// A built-in environment's model.
#[derive(Clone, Debug)]
pub enum EnvModel {
    /// Point masses (section 3.1).
    PointMass(PointMass),
    /// Khepera IV robots (sections 3.2-3.3).
    Khepera(KheperaModel),
    /// The DC motor benchmark.
    DcMotor(DcMotor),
    /// The inverted pendulum swing-up benchmark.
    Pendulum(Pendulum),
    /// The car on the hill benchmark.
    CarHill(CarHill),
    /// The two-link robot arm benchmark.
    Arm(Arm),
}

impl EnvModel {
    /// The point-mass model, if this is one.
    #[must_use]
    pub fn point_mass(&self) -> Option<&PointMass> {
        match self {
            Self::PointMass(m) => Some(m),
            _ => None,
        }
    }

    /// The Khepera model, if this is one.
    #[must_use]
    pub fn khepera(&self) -> Option<&KheperaModel> {
        match self {
            Self::Khepera(m) => Some(m),
            _ => None,
        }
    }

    /// The environment's name on the command line.
    #[must_use]
    pub fn name(&self) -> &'static str {
        match self {
            Self::PointMass(_) => "pointmass",
            Self::Khepera(_) => "khepera",
            Self::DcMotor(_) => "dcmotor",
            Self::Pendulum(_) => "pendulum",
            Self::CarHill(_) => "carhill",
            Self::Arm(_) => "arm",
        }
    }

    /// The sample time of one step (s).
    #[must_use]
    pub fn sample_time(&self) -> f64 {
        match self {
            Self::PointMass(m) => m.config().sample_time,
            Self::Khepera(m) => m.config().sample_time,
            Self::DcMotor(m) => m.config().sample_time,
            Self::Pendulum(m) => m.config().sample_time,
            Self::CarHill(m) => m.config().sample_time,
            Self::Arm(m) => m.config().sample_time,
        }
    }
}

macro_rules! dispatch {
    ($self:ident, $m:ident => $e:expr) => {
        match $self {
            EnvModel::PointMass($m) => $e,
            EnvModel::Khepera($m) => $e,
            EnvModel::DcMotor($m) => $e,
            EnvModel::Pendulum($m) => $e,
            EnvModel::CarHill($m) => $e,
            EnvModel::Arm($m) => $e,
        }
    };
}

macro_rules! impl_model {
    ($t:ty) => {
        impl Model<$t> for EnvModel {
            fn state_dim(&self) -> usize {
                dispatch!(self, m => Model::<$t>::state_dim(m))
            }
            fn n_agents(&self) -> usize {
                dispatch!(self, m => Model::<$t>::n_agents(m))
            }
            fn action_set(&self, agent: usize) -> ActionSet<'_, $t> {
                dispatch!(self, m => Model::<$t>::action_set(m, agent))
            }
            fn state_bounds(&self, dim: usize) -> ($t, $t) {
                dispatch!(self, m => Model::<$t>::state_bounds(m, dim))
            }
            fn step(&self, x: &[$t], u: &[$t], next: &mut [$t]) {
                dispatch!(self, m => Model::<$t>::step(m, x, u, next))
            }
            fn reward(&self, x: &[$t], u: &[$t]) -> $t {
                dispatch!(self, m => Model::<$t>::reward(m, x, u))
            }
            fn reward_depends_on_action(&self) -> bool {
                dispatch!(self, m => Model::<$t>::reward_depends_on_action(m))
            }
            fn is_goal(&self, x: &[$t]) -> bool {
                dispatch!(self, m => Model::<$t>::is_goal(m, x))
            }
            fn is_terminal(&self, x: &[$t]) -> bool {
                dispatch!(self, m => Model::<$t>::is_terminal(m, x))
            }
            fn has_terminal_states(&self) -> bool {
                dispatch!(self, m => Model::<$t>::has_terminal_states(m))
            }
            fn n_blocks(&self) -> usize {
                dispatch!(self, m => Model::<$t>::n_blocks(m))
            }
            fn tabulated(&self) -> Option<Tabulated<'_, $t>> {
                dispatch!(self, m => Model::<$t>::tabulated(m))
            }
            fn block(&self, b: usize) -> Block<'_> {
                dispatch!(self, m => Model::<$t>::block(m, b))
            }
        }
    };
}

impl_model!(f32);
impl_model!(f64);
