//! The environments: their models (what fuzzy Q-iteration solves and what a rollout steps)
//! and the registry that names them.
//!
//! # The registry
//! [`EnvKind`] is the one list of built-in environments. Each declares once, in its
//! [`EnvSpec`], its presets, the names of its state and action variables, its default start
//! and rollout length, its plants and its figures; the configuration, the policy files, the
//! command line and the Python package read them from here.
//!
//! # Models in `f64`, solved in either precision
//! Every built-in model computes in `f64` whatever the solver's precision: it implements
//! [`F64Model`], and `impl_model!` (applied once per model) derives
//! [`fuzzyq_core::Model`] for `f32` and `f64` from it, widening the solver's values to `f64`
//! and rounding the results once. [`EnvModel`] holds any of them behind one type, so that
//! training, policies and policy files handle every environment alike.
//!
//! - [`pointmass`]: the paper's point masses (section 3.1), `n` agents;
//! - [`khepera`]: Khepera IV robots over their poses (sections 3.2-3.3), in an [`arena`];
//! - [`classic`]: the single-agent benchmarks of Busoniu et al. 2010 (DC motor, pendulum
//!   swing-up, car on the hill, two-link arm).

pub mod arena;
pub mod classic;
pub mod khepera;
pub mod learned;
pub mod pointmass;

use fuzzyq_core::solver::Precision;
use fuzzyq_core::{ActionSet, Model, Real};

use crate::error::{ConfigError, SimError, require};
use crate::model::classic::arm::ArmModel;
use crate::model::classic::carhill::CarHillModel;
use crate::model::classic::dcmotor::DcMotorModel;
use crate::model::classic::pendulum::PendulumModel;
use crate::model::khepera::KheperaModel;
use crate::model::pointmass::PointMass;
use crate::paper;

fuzzyq_core::named_option! {
    /// The built-in environments (see the [module docs](self)).
    pub enum EnvKind: "environment" {
        /// Point masses on the plane (paper section 3.1).
        Pointmass = "pointmass" => "point masses on the plane (paper section 3.1)",
        /// Khepera IV robots with sonars (paper sections 3.2-3.3).
        Khepera = "khepera" => "two Khepera IV robots with sonars (paper sections 3.2-3.3)",
        /// The DC motor ([`classic::dcmotor`]).
        Dcmotor = "dcmotor" => "the DC motor of the classic benchmarks",
        /// The inverted pendulum swing-up ([`classic::pendulum`]).
        Pendulum = "pendulum" => "the inverted pendulum swing-up",
        /// The car on the hill ([`classic::carhill`]).
        Carhill = "carhill" => "the car on the hill",
        /// The two-link robot arm ([`classic::arm`]).
        Arm = "arm" => "the two-link robot arm",
    }
}

/// How many initial states an evaluation over many starts draws, and how.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum StartsKind {
    /// Seeded random starts at rest (the robots and the point masses).
    Random,
    /// An evenly spaced lattice over the state bounds (the classic benchmarks' score).
    Lattice,
}

/// What the registry declares about one environment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EnvSpec {
    /// Named presets of grid, actions, `gamma` and `xi` (empty for the paper's tasks).
    pub presets: &'static [&'static str],
    /// The preset used when none is named.
    pub default_preset: Option<&'static str>,
    /// Names of one agent's state variables as a rollout reports them (in CSV headers,
    /// suffixed by the agent number for multi-agent tasks). The robots report the paper's 8-D
    /// state (positions and measured velocities), not their poses.
    pub state_names: &'static [&'static str],
    /// Figure labels of the state variables (with units), one per variable of one agent.
    pub state_labels: &'static [&'static str],
    /// Names of one agent's action components (CSV headers).
    pub action_names: &'static [&'static str],
    /// Figure labels of the action components (with units).
    pub action_labels: &'static [&'static str],
    /// The default start of a rollout, in the reported state (for two agents where the task
    /// has agents).
    pub default_start: &'static [f64],
    /// The default rollout length in sample times.
    pub default_steps: usize,
    /// Whether the task has several agents (`n` point masses or robots).
    pub multi_agent: bool,
    /// Whether it is one of the classic single-agent benchmarks (presets, explicit grids).
    pub classic: bool,
    /// Whether policies can also run on the rapier point-mass plant (colliding discs).
    pub rapier_point_masses: bool,
    /// Whether policies run on the rapier robot plant only (sonars, contacts).
    pub robot_plant: bool,
    /// How an evaluation over many starts draws them.
    pub starts: StartsKind,
}

const PENDULUM_START: [f64; 2] = [-std::f64::consts::PI, 0.0];
const DCMOTOR_START: [f64; 2] = [-std::f64::consts::PI, 0.0];
const CARHILL_START: [f64; 2] = [-0.5, 0.0];
const ARM_START: [f64; 4] = [-1.0, 0.0, 1.0, 0.0];

impl EnvKind {
    /// What the registry declares about this environment.
    #[must_use]
    pub fn spec(self) -> &'static EnvSpec {
        const CLASSIC: EnvSpec = EnvSpec {
            presets: &[],
            default_preset: Some(classic::DEFAULT_PRESET),
            state_names: &["x1", "x2"],
            state_labels: &[],
            action_names: &["u1"],
            action_labels: &[],
            default_start: &[],
            default_steps: 0,
            multi_agent: false,
            classic: true,
            rapier_point_masses: false,
            robot_plant: false,
            starts: StartsKind::Lattice,
        };
        const POINTMASS: EnvSpec = EnvSpec {
            presets: &[],
            default_preset: None,
            state_names: &["sx", "sy", "vx", "vy"],
            state_labels: &["s_x (m)", "s_y (m)", "v_x (m/s)", "v_y (m/s)"],
            action_names: &["ux", "uy"],
            action_labels: &["u_x (N)", "u_y (N)"],
            default_start: &paper::X0,
            default_steps: 75,
            multi_agent: true,
            classic: false,
            rapier_point_masses: true,
            robot_plant: false,
            starts: StartsKind::Random,
        };
        const KHEPERA: EnvSpec = EnvSpec {
            action_names: &["vl", "vr"],
            action_labels: &["v_l (m/s)", "v_r (m/s)"],
            default_start: &paper::KHEPERA_X0,
            default_steps: 250,
            rapier_point_masses: false,
            robot_plant: true,
            ..POINTMASS
        };
        const DCMOTOR: EnvSpec = EnvSpec {
            presets: &classic::dcmotor::PRESETS,
            state_labels: &["angle (rad)", "angular velocity (rad/s)"],
            action_labels: &["voltage (V)"],
            default_start: &DCMOTOR_START,
            // The toolbox's replays: 2 s for the motor, 3 s for the pendulum; 10 s for the
            // car and the arm.
            default_steps: 400,
            ..CLASSIC
        };
        const PENDULUM: EnvSpec = EnvSpec {
            presets: &classic::pendulum::PRESETS,
            state_labels: &["angle (rad, 0 = up)", "angular velocity (rad/s)"],
            action_labels: &["voltage (V)"],
            default_start: &PENDULUM_START,
            default_steps: 600,
            ..CLASSIC
        };
        const CARHILL: EnvSpec = EnvSpec {
            presets: &classic::carhill::PRESETS,
            state_labels: &["position (m)", "velocity (m/s)"],
            action_labels: &["force (N)"],
            default_start: &CARHILL_START,
            default_steps: 100,
            ..CLASSIC
        };
        const ARM: EnvSpec = EnvSpec {
            presets: &classic::arm::PRESETS,
            state_names: &["x1", "x2", "x3", "x4"],
            state_labels: &[
                "angle 1 (rad)",
                "angular velocity 1 (rad/s)",
                "angle 2 (rad)",
                "angular velocity 2 (rad/s)",
            ],
            action_names: &["u1", "u2"],
            action_labels: &["torque 1 (N m)", "torque 2 (N m)"],
            default_start: &ARM_START,
            default_steps: 200,
            ..CLASSIC
        };
        match self {
            Self::Pointmass => &POINTMASS,
            Self::Khepera => &KHEPERA,
            Self::Dcmotor => &DCMOTOR,
            Self::Pendulum => &PENDULUM,
            Self::Carhill => &CARHILL,
            Self::Arm => &ARM,
        }
    }

    /// The help line of the command line's `--env`: the description and the presets.
    #[must_use]
    pub fn help_line(self) -> String {
        let presets = self.spec().presets;
        let help = fuzzyq_core::NamedOption::help(self);
        if presets.is_empty() {
            help.to_string()
        } else {
            format!("{help} (presets: {})", presets.join(", "))
        }
    }

    /// An error for a preset this environment does not have.
    #[must_use]
    pub fn unknown_preset(self, preset: &str) -> ConfigError {
        let presets = self.spec().presets;
        if presets.is_empty() {
            ConfigError::invalid(
                "preset",
                format!(
                    "the {} environment has no presets (presets belong to {})",
                    self.name(),
                    Self::with_presets().join(", ")
                ),
            )
        } else {
            ConfigError::invalid(
                "preset",
                format!(
                    "unknown {} preset \"{preset}\" (known: {})",
                    self.name(),
                    presets.join(", ")
                ),
            )
        }
    }

    /// The names of the environments that have presets.
    #[must_use]
    pub fn with_presets() -> Vec<&'static str> {
        <Self as fuzzyq_core::NamedOption>::ALL
            .iter()
            .filter(|k| !k.spec().presets.is_empty())
            .map(|k| k.name())
            .collect()
    }

    /// The environment named `name`, or an error listing the known ones.
    pub fn parse(name: &str) -> Result<Self, ConfigError> {
        name.parse()
            .map_err(|e: fuzzyq_core::options::UnknownName| {
                ConfigError::invalid("env", format!("{name:?}: {e}"))
            })
    }
}

/// The discrete actions of one agent in both precisions: every agent of a built-in model has
/// the same set.
#[derive(Clone, Debug, PartialEq)]
pub struct ActionTable {
    f64s: Vec<f64>,
    f32s: Vec<f32>,
    dim: usize,
}

impl ActionTable {
    /// `values` holds `dim` components per action, action-major (finite, at least one
    /// action: the caller validates them).
    #[must_use]
    pub fn new(values: Vec<f64>, dim: usize) -> Self {
        Self {
            f32s: values.iter().map(|&v| v as f32).collect(),
            f64s: values,
            dim,
        }
    }

    /// Components per action.
    #[must_use]
    pub fn dim(&self) -> usize {
        self.dim
    }

    /// Number of actions.
    #[must_use]
    pub fn len(&self) -> usize {
        self.f64s.len() / self.dim.max(1)
    }

    /// Whether there are no actions (never, for a validated model).
    #[must_use]
    pub fn is_empty(&self) -> bool {
        self.f64s.is_empty()
    }

    /// The components of action `j` in `f64`.
    ///
    /// # Panics
    /// If `j` is out of range.
    #[must_use]
    pub fn action(&self, j: usize) -> &[f64] {
        &self.f64s[j * self.dim..(j + 1) * self.dim]
    }

    /// Every component, action-major, in `f64`.
    #[must_use]
    pub fn values(&self) -> &[f64] {
        &self.f64s
    }

    /// The set in precision `T`.
    #[must_use]
    pub fn set<T: Wide>(&self) -> ActionSet<'_, T> {
        ActionSet::try_new(T::pick(&self.f32s, &self.f64s), self.dim)
            .expect("a model validates its actions")
    }
}

/// The dynamics of a model computed in `f64`: its transition `f` and reward `rho`, and what it
/// says about single states (bounds, periodic variables, goals, terminal states). The one place
/// these are declared for every built-in model: [`F64Model`] adds the agents, actions and
/// blocks; [`classic::Benchmark`] adds a classic benchmark's parameters and presets.
pub trait Dynamics {
    /// The sample time of one step (s).
    fn sample_time(&self) -> f64;
    /// The range of state variable `dim`.
    fn state_bounds(&self, dim: usize) -> (f64, f64);
    /// Whether state variable `dim` is periodic over its range (an angle wrapped to
    /// `(lo, hi]`, such as a robot's heading): its ends are one state, and a step across them
    /// wraps. Part of the task's description, which a learner of the dynamics is told.
    fn is_periodic(&self, dim: usize) -> bool {
        let _ = dim;
        false
    }
    /// The successor of `x` under the joint action vector `u`.
    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]);
    /// The reward of `u` at `x`. `precision` is the solver's: a model whose reward depends on
    /// the successor (the car on the hill) rounds the successor to it, as the solver sees it.
    fn reward(&self, x: &[f64], u: &[f64], precision: Precision) -> f64;
    /// See [`Model::reward_depends_on_action`].
    fn reward_depends_on_action(&self) -> bool {
        true
    }
    /// See [`Model::reward_depends_on_state`].
    fn reward_depends_on_state(&self, dim: usize) -> bool {
        let _ = dim;
        true
    }
    /// See [`Model::is_goal`].
    fn is_goal(&self, x: &[f64]) -> bool {
        let _ = x;
        false
    }
    /// See [`Model::is_terminal`].
    fn is_terminal(&self, x: &[f64]) -> bool {
        let _ = x;
        false
    }
    /// See [`Model::has_terminal_states`].
    fn has_terminal_states(&self) -> bool {
        false
    }
}

/// The symmetric range `[-lim, lim]` (a state variable's bounds in most models).
#[must_use]
pub fn symmetric(lim: f64) -> (f64, f64) {
    (-lim, lim)
}

/// A model computed in `f64`: what every built-in model implements, its [`Dynamics`] with the
/// agents, their discrete actions and the dynamics blocks. `impl_model!` turns it into
/// [`fuzzyq_core::Model`] for `f32` and `f64`.
pub trait F64Model: Dynamics {
    /// Length of the state vector.
    fn state_dim(&self) -> usize;
    /// Number of agents.
    fn n_agents(&self) -> usize;
    /// Every agent's discrete actions.
    fn actions(&self) -> &ActionTable;
    /// The independent dynamics blocks (see [`Model::block`]).
    fn blocks(&self) -> &[BlockSpec];
    /// Block `b`'s transition table, if the model gives it directly (a learned model, see
    /// [`Model::block_rows`]); `None` (the default) for a model that steps.
    fn block_rows(&self, b: usize) -> Option<WideBlockRows<'_>> {
        let _ = b;
        None
    }
    /// Adds the plant's process noise to a successor `x` drawn from `rng` (the default has
    /// none). The model's [`step`](Dynamics::step) stays the noise-free transition; plants and
    /// data collection call this after it.
    fn add_process_noise(&self, x: &mut [f64], rng: &mut rand_pcg::Pcg64Mcg) {
        let _ = (x, rng);
    }
}

/// A block table in both precisions, as [`F64Model::block_rows`] gives it (see
/// [`fuzzyq_core::BlockRows`]).
#[derive(Clone, Copy, Debug)]
pub struct WideBlockRows<'a> {
    /// Number of block actions.
    pub n_actions: usize,
    /// The action components' values per block action, in `f32` and `f64`.
    pub actions: (&'a [f32], &'a [f64]),
    /// Row starts.
    pub ptr: &'a [u32],
    /// Block core of each entry.
    pub col: &'a [u32],
    /// Expected membership of each entry, in `f32` and `f64`.
    pub weight: (&'a [f32], &'a [f64]),
}

/// A dynamics block as a model stores it (see [`fuzzyq_core::Block`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BlockSpec {
    /// The block's state variables.
    pub state_dims: Vec<usize>,
    /// The joint-action components it depends on.
    pub action_components: Vec<usize>,
}

/// The two precisions a model is solved in, widened to `f64` for [`F64Model`].
pub trait Wide: Real {
    /// The solver precision of this type.
    const PRECISION: Precision;
    /// The slice of this precision.
    fn pick<'a>(f32s: &'a [f32], f64s: &'a [f64]) -> &'a [Self];
    /// Runs `f` on `x` as `f64` values (without copying for `f64`).
    fn widened<R>(x: &[Self], f: impl FnOnce(&[f64]) -> R) -> R;
    /// Runs `f` on an `f64` buffer of `out.len()` values and rounds them into `out`.
    fn narrowed(out: &mut [Self], f: impl FnOnce(&mut [f64]));
}

/// Longest state a stack buffer widens (longer ones use the heap).
const WIDE_STACK: usize = 32;

impl Wide for f64 {
    const PRECISION: Precision = Precision::F64;
    fn pick<'a>(_: &'a [f32], f64s: &'a [f64]) -> &'a [f64] {
        f64s
    }
    #[inline]
    fn widened<R>(x: &[f64], f: impl FnOnce(&[f64]) -> R) -> R {
        f(x)
    }
    #[inline]
    fn narrowed(out: &mut [f64], f: impl FnOnce(&mut [f64])) {
        f(out);
    }
}

impl Wide for f32 {
    const PRECISION: Precision = Precision::F32;
    fn pick<'a>(f32s: &'a [f32], _: &'a [f64]) -> &'a [f32] {
        f32s
    }
    #[inline]
    fn widened<R>(x: &[f32], f: impl FnOnce(&[f64]) -> R) -> R {
        if x.len() <= WIDE_STACK {
            let mut buf = [0.0f64; WIDE_STACK];
            for (a, &b) in buf.iter_mut().zip(x) {
                *a = f64::from(b);
            }
            f(&buf[..x.len()])
        } else {
            f(&x.iter().map(|&v| f64::from(v)).collect::<Vec<f64>>())
        }
    }
    #[inline]
    fn narrowed(out: &mut [f32], f: impl FnOnce(&mut [f64])) {
        let mut heap;
        let mut stack = [0.0f64; WIDE_STACK];
        let buf = if out.len() <= WIDE_STACK {
            &mut stack[..out.len()]
        } else {
            heap = vec![0.0; out.len()];
            &mut heap[..]
        };
        f(buf);
        for (a, &b) in out.iter_mut().zip(buf.iter()) {
            *a = b as f32;
        }
    }
}

/// Implements [`fuzzyq_core::Model`] for `f32` and `f64` on a type that implements
/// [`F64Model`]: the solver's values are widened to `f64`, the model computes, the results are
/// rounded once. The one place where a model meets the solver's precision.
macro_rules! impl_model {
    ($ty:ty) => {
        $crate::model::impl_model!(@impl [] $ty);
    };
    ($ty:ty where $($p:ident: $b:path),+) => {
        $crate::model::impl_model!(@impl [$($p: $b),+] $ty);
    };
    (@impl [$($g:tt)*] $ty:ty) => {
        impl<T: $crate::model::Wide, $($g)*> ::fuzzyq_core::Model<T> for $ty {
            fn state_dim(&self) -> usize {
                $crate::model::F64Model::state_dim(self)
            }
            fn n_agents(&self) -> usize {
                $crate::model::F64Model::n_agents(self)
            }
            fn action_set(&self, _agent: usize) -> ::fuzzyq_core::ActionSet<'_, T> {
                $crate::model::F64Model::actions(self).set::<T>()
            }
            fn state_bounds(&self, dim: usize) -> (T, T) {
                let (lo, hi) = $crate::model::Dynamics::state_bounds(self, dim);
                (T::from_f64(lo), T::from_f64(hi))
            }
            fn step(&self, x: &[T], u: &[T], next: &mut [T]) {
                T::widened(x, |x| {
                    T::widened(u, |u| {
                        T::narrowed(next, |next| $crate::model::Dynamics::step(self, x, u, next))
                    })
                });
            }
            fn reward(&self, x: &[T], u: &[T]) -> T {
                T::from_f64(T::widened(x, |x| {
                    T::widened(u, |u| {
                        $crate::model::Dynamics::reward(self, x, u, T::PRECISION)
                    })
                }))
            }
            fn reward_depends_on_action(&self) -> bool {
                $crate::model::Dynamics::reward_depends_on_action(self)
            }
            fn reward_depends_on_state(&self, dim: usize) -> bool {
                $crate::model::Dynamics::reward_depends_on_state(self, dim)
            }
            fn is_goal(&self, x: &[T]) -> bool {
                T::widened(x, |x| $crate::model::Dynamics::is_goal(self, x))
            }
            fn is_terminal(&self, x: &[T]) -> bool {
                T::widened(x, |x| $crate::model::Dynamics::is_terminal(self, x))
            }
            fn has_terminal_states(&self) -> bool {
                $crate::model::Dynamics::has_terminal_states(self)
            }
            fn n_blocks(&self) -> usize {
                $crate::model::F64Model::blocks(self).len()
            }
            fn block_rows(&self, b: usize) -> Option<::fuzzyq_core::BlockRows<'_, T>> {
                $crate::model::F64Model::block_rows(self, b).map(|r| ::fuzzyq_core::BlockRows {
                    n_actions: r.n_actions,
                    actions: T::pick(r.actions.0, r.actions.1),
                    ptr: r.ptr,
                    col: r.col,
                    weight: T::pick(r.weight.0, r.weight.1),
                })
            }
            fn block(&self, b: usize) -> ::fuzzyq_core::Block<'_> {
                let spec = &$crate::model::F64Model::blocks(self)[b];
                ::fuzzyq_core::Block {
                    state_dims: &spec.state_dims,
                    action_components: &spec.action_components,
                }
            }
        }
    };
}
pub(crate) use impl_model;

/// A built-in environment's model.
#[derive(Clone, Debug)]
pub enum EnvModel {
    /// Point masses (section 3.1).
    PointMass(PointMass),
    /// Khepera IV robots (sections 3.2-3.3).
    Khepera(KheperaModel),
    /// The DC motor benchmark.
    DcMotor(DcMotorModel),
    /// The inverted pendulum swing-up benchmark.
    Pendulum(PendulumModel),
    /// The car on the hill benchmark.
    CarHill(CarHillModel),
    /// The two-link robot arm benchmark.
    Arm(ArmModel),
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

    /// The environment.
    #[must_use]
    pub fn kind(&self) -> EnvKind {
        match self {
            Self::PointMass(_) => EnvKind::Pointmass,
            Self::Khepera(_) => EnvKind::Khepera,
            Self::DcMotor(_) => EnvKind::Dcmotor,
            Self::Pendulum(_) => EnvKind::Pendulum,
            Self::CarHill(_) => EnvKind::Carhill,
            Self::Arm(_) => EnvKind::Arm,
        }
    }

    /// The environment's name on the command line.
    #[must_use]
    pub fn name(&self) -> &'static str {
        self.kind().name()
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

impl Dynamics for EnvModel {
    fn sample_time(&self) -> f64 {
        dispatch!(self, m => Dynamics::sample_time(m))
    }
    fn state_bounds(&self, dim: usize) -> (f64, f64) {
        dispatch!(self, m => Dynamics::state_bounds(m, dim))
    }
    fn is_periodic(&self, dim: usize) -> bool {
        dispatch!(self, m => Dynamics::is_periodic(m, dim))
    }
    fn step(&self, x: &[f64], u: &[f64], next: &mut [f64]) {
        dispatch!(self, m => Dynamics::step(m, x, u, next))
    }
    fn reward(&self, x: &[f64], u: &[f64], precision: Precision) -> f64 {
        dispatch!(self, m => Dynamics::reward(m, x, u, precision))
    }
    fn reward_depends_on_action(&self) -> bool {
        dispatch!(self, m => Dynamics::reward_depends_on_action(m))
    }
    fn reward_depends_on_state(&self, dim: usize) -> bool {
        dispatch!(self, m => Dynamics::reward_depends_on_state(m, dim))
    }
    fn is_goal(&self, x: &[f64]) -> bool {
        dispatch!(self, m => Dynamics::is_goal(m, x))
    }
    fn is_terminal(&self, x: &[f64]) -> bool {
        dispatch!(self, m => Dynamics::is_terminal(m, x))
    }
    fn has_terminal_states(&self) -> bool {
        dispatch!(self, m => Dynamics::has_terminal_states(m))
    }
}

impl F64Model for EnvModel {
    fn state_dim(&self) -> usize {
        dispatch!(self, m => F64Model::state_dim(m))
    }
    fn n_agents(&self) -> usize {
        dispatch!(self, m => F64Model::n_agents(m))
    }
    fn actions(&self) -> &ActionTable {
        dispatch!(self, m => F64Model::actions(m))
    }
    fn blocks(&self) -> &[BlockSpec] {
        dispatch!(self, m => F64Model::blocks(m))
    }
    fn add_process_noise(&self, x: &mut [f64], rng: &mut rand_pcg::Pcg64Mcg) {
        dispatch!(self, m => F64Model::add_process_noise(m, x, rng))
    }
}

impl_model!(EnvModel);

/// Checks that `x0` is a state of `model`: the right length, finite, within the bounds.
pub fn check_state<M: Model<f64> + ?Sized>(model: &M, x0: &[f64]) -> Result<(), SimError> {
    Ok(check_state_as("x0", model, x0)?)
}

/// [`check_state`] with the errors naming `field`.
pub fn check_state_as<M: Model<f64> + ?Sized>(
    field: &str,
    model: &M,
    x0: &[f64],
) -> Result<(), ConfigError> {
    let n = Model::<f64>::state_dim(model);
    require!(
        x0.len() == n,
        field,
        format!("needs {n} values (the state length), got {}", x0.len()),
    );
    for (i, &v) in x0.iter().enumerate() {
        let (lo, hi) = Model::<f64>::state_bounds(model, i);
        require!(
            v >= lo && v <= hi,
            field,
            format!("x0[{i}] = {v} is outside the state range [{lo}, {hi}]"),
        );
    }
    Ok(())
}
