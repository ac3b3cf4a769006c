//! The model of any environment a configuration can name, behind one type.
//!
//! [`EnvModel`] dispatches the [`Model`] trait to the point masses or the Khepera robots, so
//! that training, policies and policy files handle every environment alike.

use fuzzyq_core::{ActionSet, Block, Model, Tabulated};

use crate::khepera::KheperaModel;
use crate::pointmass::PointMass;

/// A built-in environment's model.
#[derive(Clone, Debug)]
pub enum EnvModel {
    /// Point masses (section 3.1).
    PointMass(PointMass),
    /// Khepera IV robots (sections 3.2-3.3).
    Khepera(KheperaModel),
}

impl EnvModel {
    /// The point-mass model, if this is one.
    #[must_use]
    pub fn point_mass(&self) -> Option<&PointMass> {
        match self {
            Self::PointMass(m) => Some(m),
            Self::Khepera(_) => None,
        }
    }

    /// The Khepera model, if this is one.
    #[must_use]
    pub fn khepera(&self) -> Option<&KheperaModel> {
        match self {
            Self::Khepera(m) => Some(m),
            Self::PointMass(_) => None,
        }
    }

    /// The environment's name on the command line.
    #[must_use]
    pub fn name(&self) -> &'static str {
        match self {
            Self::PointMass(_) => "pointmass",
            Self::Khepera(_) => "khepera",
        }
    }
}

macro_rules! dispatch {
    ($self:ident, $m:ident => $e:expr) => {
        match $self {
            EnvModel::PointMass($m) => $e,
            EnvModel::Khepera($m) => $e,
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
