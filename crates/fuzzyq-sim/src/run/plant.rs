//! Plants: what a policy acts on, one sample time per step.
//!
//! - [`ModelPlant`]: any environment's model, integrated in `f64` (a run ends at a terminal
//!   state of the model);
//! - [`RapierPointMasses`]: the point masses as colliding discs ([`PointMassPlant`]);
//! - [`KheperaPlant`]: the Khepera robots with sonars and contacts ([`KheperaWorld`]),
//!   reporting the paper's 8-D state and logging poses, sonars and action indices.
//!
//! A controller sees an [`Observation`]: the state the policy was trained on (the model's
//! state; the robots' poses) and, on the robot plant, the sonar readings.

use fuzzyq_core::Model;
use fuzzyq_core::error::check_len;
use rand::SeedableRng;
use rand_pcg::Pcg64Mcg;

use crate::error::SimError;
use crate::model::khepera::{KheperaConfig, KheperaModel, N_ACTIONS};
use crate::model::pointmass::PointMass;
use crate::model::{Dynamics, F64Model, check_state};
use crate::run::metrics::{KheperaRun, Trajectory};
use crate::world::{Collisions, KheperaWorld, PointMassPlant, PointMassPlantConfig};

/// What a controller sees before each decision.
#[derive(Clone, Copy, Debug)]
pub struct Observation<'a> {
    /// The state the policy was trained on: the model's state (for the robot plant, the poses
    /// `(x, y, heading)` of every robot).
    pub state: &'a [f64],
    /// Sonar readings per robot (the robot plant only; empty otherwise).
    pub sonar: &'a [Vec<f64>],
}

/// A system a policy acts on (see the [module docs](self)).
pub trait Plant {
    /// The model the plant follows (its sample time, agents and actions).
    fn model(&self) -> &dyn F64Model;
    /// The sample time of one step (s).
    fn sample_time(&self) -> f64 {
        self.model().sample_time()
    }
    /// Number of agents.
    fn n_agents(&self) -> usize {
        self.model().n_agents()
    }
    /// Length of the joint action vector.
    fn action_dim(&self) -> usize {
        self.model().n_agents() * self.model().actions().dim()
    }
    /// Starts a run at `start` (a model state; the robots' flat poses for the robot plant).
    fn reset(&mut self, start: &[f64]) -> Result<(), SimError>;
    /// What a controller sees now.
    fn observe(&self) -> Observation<'_>;
    /// The state a trajectory records now.
    fn recorded_state(&self) -> Vec<f64>;
    /// The reward of acting `u` now.
    fn reward(&self, u: &[f64]) -> f64;
    /// Advances one sample time under `u`; `true` if the new state is terminal.
    fn step(&mut self, u: &[f64]) -> Result<bool, SimError>;
}

/// A model as the plant: the model's own `f64` transition, plus its process noise
/// ([`F64Model::add_process_noise`]) drawn from a seeded generator.
#[derive(Debug)]
pub struct ModelPlant<'m, M> {
    model: &'m M,
    x: Vec<f64>,
    next: Vec<f64>,
    rng: Pcg64Mcg,
}

impl<'m, M: F64Model + Model<f64>> ModelPlant<'m, M> {
    /// The plant of `model`, its noise seeded with 0.
    pub fn new(model: &'m M) -> Self {
        Self::seeded(model, 0)
    }

    /// The plant of `model`, its noise seeded with `seed`.
    pub fn seeded(model: &'m M, seed: u64) -> Self {
        let n = F64Model::state_dim(model);
        Self {
            model,
            x: vec![0.0; n],
            next: vec![0.0; n],
            rng: Pcg64Mcg::seed_from_u64(seed),
        }
    }
}

impl<M: F64Model + Model<f64>> Plant for ModelPlant<'_, M> {
    fn model(&self) -> &dyn F64Model {
        self.model
    }
    fn reset(&mut self, start: &[f64]) -> Result<(), SimError> {
        check_state(self.model, start)?;
        self.x.copy_from_slice(start);
        Ok(())
    }
    fn observe(&self) -> Observation<'_> {
        Observation {
            state: &self.x,
            sonar: &[],
        }
    }
    fn recorded_state(&self) -> Vec<f64> {
        self.x.clone()
    }
    fn reward(&self, u: &[f64]) -> f64 {
        Model::<f64>::reward(self.model, &self.x, u)
    }
    fn step(&mut self, u: &[f64]) -> Result<bool, SimError> {
        Dynamics::step(self.model, &self.x, u, &mut self.next);
        F64Model::add_process_noise(self.model, &mut self.next, &mut self.rng);
        std::mem::swap(&mut self.x, &mut self.next);
        Ok(Dynamics::has_terminal_states(self.model) && Dynamics::is_terminal(self.model, &self.x))
    }
}

/// The point masses as colliding discs on the rapier plant; rewards are the model's.
#[derive(Debug)]
pub struct RapierPointMasses<'m> {
    model: &'m PointMass,
    world: PointMassPlant,
}

impl<'m> RapierPointMasses<'m> {
    /// The plant of `model` with discs of `config`.
    pub fn new(model: &'m PointMass, config: &PointMassPlantConfig) -> Result<Self, SimError> {
        Ok(Self {
            model,
            world: PointMassPlant::new(model, config)?,
        })
    }

    /// The collisions so far.
    #[must_use]
    pub fn collisions(&self) -> &Collisions {
        self.world.collisions()
    }
}

impl Plant for RapierPointMasses<'_> {
    fn model(&self) -> &dyn F64Model {
        self.model
    }
    fn reset(&mut self, start: &[f64]) -> Result<(), SimError> {
        check_state(self.model, start)?;
        self.world.reset(start)
    }
    fn observe(&self) -> Observation<'_> {
        Observation {
            state: self.world.state(),
            sonar: &[],
        }
    }
    fn recorded_state(&self) -> Vec<f64> {
        self.world.state().to_vec()
    }
    fn reward(&self, u: &[f64]) -> f64 {
        Model::<f64>::reward(self.model, self.world.state(), u)
    }
    fn step(&mut self, u: &[f64]) -> Result<bool, SimError> {
        self.world.step(u)?;
        Ok(false)
    }
}

/// The Khepera robots on the rapier plant. The trajectory records the paper's 8-D state
/// `[s_1x, s_1y, v_1x, v_1y, ...]` (velocity: displacement over the last control period);
/// the plant logs the poses, the sonar readings and the action index of every step
/// ([`into_run`](Self::into_run)).
#[derive(Debug)]
pub struct KheperaPlant<'m> {
    model: &'m KheperaModel,
    world: KheperaWorld,
    poses: Vec<f64>,
    sonar: Vec<Vec<f64>>,
    started: bool,
    log_poses: Vec<Vec<[f64; 3]>>,
    log_sonar: Vec<Vec<Vec<f64>>>,
    log_actions: Vec<Vec<usize>>,
    wheels: Vec<[f64; 2]>,
}

impl<'m> KheperaPlant<'m> {
    /// The plant of `model` with its noise seeded by `seed`.
    pub fn new(model: &'m KheperaModel, seed: u64) -> Result<Self, SimError> {
        let config = model.config();
        Ok(Self {
            world: KheperaWorld::new(config, seed)?,
            model,
            poses: Vec::with_capacity(3 * config.agents),
            sonar: vec![vec![0.0; config.sonar_angles_deg.len()]; config.agents],
            started: false,
            log_poses: Vec::new(),
            log_sonar: Vec::new(),
            log_actions: Vec::new(),
            wheels: vec![[0.0; 2]; config.agents],
        })
    }

    /// The collisions so far.
    #[must_use]
    pub fn collisions(&self) -> &Collisions {
        self.world.collisions()
    }

    /// The run of `trajectory` (recorded on this plant) with the plant's logs.
    #[must_use]
    pub fn into_run(self, trajectory: Trajectory) -> KheperaRun {
        KheperaRun {
            trajectory,
            poses: self.log_poses,
            action_indices: self.log_actions,
            sonar: self.log_sonar,
        }
    }

    /// Reads every robot's sonars and logs the poses and readings.
    fn sense(&mut self) -> Result<(), SimError> {
        for (r, s) in self.sonar.iter_mut().enumerate() {
            self.world.sonar(r, s)?;
        }
        self.poses.clear();
        self.poses.extend(self.world.poses().iter().flatten());
        self.log_poses.push(self.world.poses().to_vec());
        self.log_sonar.push(self.sonar.clone());
        Ok(())
    }
}

/// The action of the four whose wheel speeds are nearest to `w`.
fn nearest_action(config: &KheperaConfig, w: [f64; 2]) -> usize {
    (0..N_ACTIONS)
        .min_by(|&a, &b| {
            let d = |k: usize| {
                let c = config.wheels(k);
                (c[0] - w[0]).powi(2) + (c[1] - w[1]).powi(2)
            };
            d(a).total_cmp(&d(b))
        })
        .unwrap_or(3)
}

impl Plant for KheperaPlant<'_> {
    fn model(&self) -> &dyn F64Model {
        self.model
    }
    fn reset(&mut self, start: &[f64]) -> Result<(), SimError> {
        check_len("start", 3 * self.model.config().agents, start.len())?;
        let poses: Vec<[f64; 3]> = start.chunks_exact(3).map(|p| [p[0], p[1], p[2]]).collect();
        self.world.reset(&poses)?;
        self.started = false;
        self.log_poses.clear();
        self.log_sonar.clear();
        self.log_actions.clear();
        self.sense()
    }
    fn observe(&self) -> Observation<'_> {
        Observation {
            state: &self.poses,
            sonar: &self.sonar,
        }
    }
    fn recorded_state(&self) -> Vec<f64> {
        let (poses, vel) = (self.world.poses(), self.world.velocities());
        (0..poses.len())
            .flat_map(|i| {
                let v = if self.started { vel[i] } else { [0.0, 0.0] };
                [poses[i][0], poses[i][1], v[0], v[1]]
            })
            .collect()
    }
    fn reward(&self, _u: &[f64]) -> f64 {
        self.model.reward_f64(&self.poses)
    }
    fn step(&mut self, u: &[f64]) -> Result<bool, SimError> {
        for (i, w) in self.wheels.iter_mut().enumerate() {
            *w = [u[2 * i], u[2 * i + 1]];
        }
        let config = self.model.config();
        self.log_actions.push(
            self.wheels
                .iter()
                .map(|w| nearest_action(config, *w))
                .collect(),
        );
        self.world.step(&self.wheels)?;
        self.started = true;
        self.sense()?;
        Ok(false)
    }
}
