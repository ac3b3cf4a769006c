//! Training configurations: the environment, the fuzzy grid and the solver settings, as one
//! TOML document. `fuzzyq config --env pointmass` prints [`DEFAULT_POINTMASS_TOML`], the
//! paper's values with a comment on every field.

use fuzzyq_core::solver::{
    BackupPath, Device, Grid, IterationOperator, Kernel, Precision, SolverConfig, SweepMode,
};
use fuzzyq_core::{Membership, Partition, Real};
use serde::{Deserialize, Serialize};
use toml::Spanned;
use toml::de::DeValue;

pub(crate) use crate::toml_doc::{TomlDoc, TomlError, line_at};

use crate::error::{ConfigError, SimError, discount, positive, require};
use crate::model::classic::arm::{Arm, ArmConfig};
use crate::model::classic::carhill::{CarHill, CarHillConfig};
use crate::model::classic::dcmotor::{DcMotor, DcMotorConfig};
use crate::model::classic::pendulum::{Pendulum, PendulumConfig};
use crate::model::classic::{self, Benchmark, Classic};
use crate::model::khepera::{self, KheperaConfig, KheperaModel};
use crate::model::pointmass::{PointMass, PointMassConfig, RewardShape};
use crate::model::{EnvKind, EnvModel};
use crate::paper;

/// The default point-mass configuration: the paper's section 3.1.
pub const DEFAULT_POINTMASS_TOML: &str = r#"# fuzzyq training configuration: the point-mass task of Luviano-Cruz et al. 2018, section 3.1.
# Edit and pass back with `fuzzyq train --env pointmass --config FILE.toml`.

[env]
kind = "pointmass"
agents = 2                                  # point masses (1 to 4)
mass = 0.5                                  # kg, every agent
sample_time = 0.4                           # s, zero-order hold
position_limit = 6.0                        # m: positions are clamped to [-6, 6]
velocity_limit = 3.0                        # m/s: velocities are clamped to [-3, 3]
force_levels = [-2.0, -0.2, 0.0, 0.2, 2.0]  # N per axis; actions are their square (25 per agent)
goal_radius = 0.1                           # reward region ||x||_2 < 0.1 over the whole state
goal_reward = 5.0                           # reward inside the region (eq 40)
integrator = "exact"                        # "exact" (constant friction) or "rk4"
rk4_substeps = 10                           # substeps per sample time for "rk4"
velocity_noise = 0.0                        # m/s: std dev of Gaussian process noise on every velocity per step (the plant's; 0 = the paper's)
reward = "paper"                            # "paper", or "shaped": plus gamma Phi(x') - Phi(x), Phi = -sum of the agents' distances to the goal (same optimal policy)
shaping_discount = 0.96                     # the shaping's gamma: must equal solver.gamma

[env.friction]
kind = "constant"                           # or "patches" with base = ..., patches = [{ center = [x, y], radius = r, eta = e }]
eta = 1.0                                   # kg/s

[grid]
# Triangular membership cores, the same on every agent and axis (paper figure 1).
position_cores = [-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0]
velocity_cores = [-3.0, -1.0, 0.0, 1.0, 3.0]
membership = "triangular"                   # "triangular" (fuzzy) or "crisp" (nearest-core boxes)

[solver]
gamma = 0.96                                # discount factor
xi = 0.05                                   # stop when ||theta_{k+1} - theta_k||_inf <= xi
max_sweeps = 1000
sweep = "sync"                              # "sync" (Jacobi, the paper) or "async" (Gauss-Seidel)
absorbing_goal = false                      # true: goal states collect their reward, then nothing
backup = "auto"                             # "auto", "block" or "generic"
precision = "f32"                           # "f32" or "f64"
extrapolate = true                          # MacQueen extrapolation: fewer sweeps, same guarantee; false = the paper's plain sweeps
evaluation_sweeps = 5                       # modified policy iteration: evaluation sweeps per full backup; 0 = value iteration (the paper)
coarse_start = false                        # true: start from the grid with every other core (same bound; pays on fine grids)
device = "cpu"                              # "cpu" or "gpu" (the block path in f32 through wgpu; the CPU's bits where the GPU fuses multiply-adds)
"#;

/// The default Khepera configuration: the robot experiment of sections 3.2-3.3.
pub const DEFAULT_KHEPERA_TOML: &str = r#"# fuzzyq training configuration: two Khepera IV robots (Luviano-Cruz et al. 2018, sections 3.2-3.3).
# Edit and pass back with `fuzzyq train --env khepera --config FILE.toml`; `--arena FILE.toml`
# replaces [env.arena].

[env]
kind = "khepera"
agents = 2                                  # robots (1 to 4)
radius = 0.07                               # m: the robot is a 140 mm disc
wheel_base = 0.105                          # m
max_wheel_speed = 0.8                       # m/s, the Khepera IV's top speed
forward_speed = 0.15                        # m/s, both wheels, action "forward"
turn_speed = 0.05                           # m/s, wheels opposite, actions "turn_cw" / "turn_ccw"
sample_time = 0.4                           # s, control period
goal_radius = 0.2                           # reward region ||x|| < 0.2 (eq 42)
goal_reward = 5.0
collision_penalty = 5.0                     # reward -5 where two robots overlap
sonar_angles_deg = [-90.0, -45.0, 0.0, 45.0, 90.0]
sonar_cone_deg = 20.0                       # each sonar casts rays_per_sonar rays over this cone
rays_per_sonar = 3
sonar_min_range = 0.25                      # m
sonar_max_range = 2.0                       # m; no echo reads this
sonar_levels = [0.5, 1.0]                   # m: near below 0.5, medium below 1.0, far above
distance_edges = [0.2, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0, 6.0]  # m: goal distance levels 0-8

[env.arena]
x = [-6.0, 6.0]                             # m, walls
y = [-6.0, 6.0]
# [[env.arena.obstacle]]
# shape = "box"                             # or "disc" with center and radius
# center = [-2.0, 2.5]
# half_extents = [0.5, 0.05]
# angle_deg = 38.66

[env.noise]
sonar_std = 0.0                             # m, Gaussian noise on sonar readings
sonar_dropout = 0.0                         # probability a reading is lost
wheel_std = 0.0                             # relative Gaussian noise on wheel speeds

[grid]
# Cores on each robot's pose: x and y share position_cores, heading_cores are radians.
position_cores = [-6.0, -4.0, -2.5, -1.5, -0.8, -0.4, -0.2, -0.1, -0.05, 0.0, 0.05, 0.1, 0.2, 0.4, 0.8, 1.5, 2.5, 4.0, 6.0]
heading_divisions = 16                      # heading cores at -pi + 2 pi k / 16, k = 0..16

[solver]
gamma = 0.96
xi = 0.2                                    # the paper's value for the robots
max_sweeps = 1000
sweep = "sync"
absorbing_goal = false
backup = "auto"
precision = "f32"
extrapolate = true
evaluation_sweeps = 5
coarse_start = true                         # start from the grid with every other core (same bound, fewer sweeps)
device = "cpu"                              # "cpu" or "gpu" (the block path in f32 through wgpu)
"#;

/// A whole training configuration.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TrainConfig {
    /// The environment (model) and its parameters.
    pub env: EnvConfig,
    /// The fuzzy grid.
    pub grid: GridConfig,
    /// Solver settings.
    pub solver: SolverSettings,
}

/// The environments fuzzyq can train on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum EnvConfig {
    /// Point masses on the plane (section 3.1).
    Pointmass(PointMassConfig),
    /// Khepera IV robots (sections 3.2-3.3).
    Khepera(KheperaConfig),
    /// The DC motor of the classic benchmarks ([`crate::model::classic::dcmotor`]).
    Dcmotor(ClassicEnv<DcMotorConfig>),
    /// The inverted pendulum swing-up ([`crate::model::classic::pendulum`]).
    Pendulum(ClassicEnv<PendulumConfig>),
    /// The car on the hill ([`crate::model::classic::carhill`]).
    Carhill(ClassicEnv<CarHillConfig>),
    /// The two-link robot arm ([`crate::model::classic::arm`]); its `actions` are torque levels as
    /// fractions of each joint's maximum torque, combined per joint.
    Arm(ClassicEnv<ArmConfig>),
}

/// A classic single-agent benchmark in a config file: its discrete actions under `[env]`, its
/// physical parameters under `[env.model]` (every field optional, defaulting to the classic
/// values). Its grid is given explicitly as `[grid] cores = [[...], [...]]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClassicEnv<C> {
    /// The discrete actions, increasing.
    pub actions: Vec<f64>,
    /// The model's parameters.
    #[serde(default)]
    pub model: C,
}

impl EnvConfig {
    /// The environment.
    #[must_use]
    pub fn kind(&self) -> EnvKind {
        match self {
            Self::Pointmass(_) => EnvKind::Pointmass,
            Self::Khepera(_) => EnvKind::Khepera,
            Self::Dcmotor(_) => EnvKind::Dcmotor,
            Self::Pendulum(_) => EnvKind::Pendulum,
            Self::Carhill(_) => EnvKind::Carhill,
            Self::Arm(_) => EnvKind::Arm,
        }
    }

    /// The name used on the command line (`--env`).
    #[must_use]
    pub fn name(&self) -> &'static str {
        self.kind().name()
    }

    /// Whether this is a classic single-agent benchmark (explicit grid, presets).
    #[must_use]
    pub fn is_classic(&self) -> bool {
        self.kind().spec().classic
    }

    /// Length of the state vector.
    #[must_use]
    pub fn state_dim(&self) -> usize {
        match self {
            Self::Pointmass(p) => p.state_dim(),
            Self::Khepera(k) => k.state_dim(),
            Self::Dcmotor(_) => DcMotor::STATE_DIM,
            Self::Pendulum(_) => Pendulum::STATE_DIM,
            Self::Carhill(_) => CarHill::STATE_DIM,
            Self::Arm(_) => Arm::STATE_DIM,
        }
    }

    /// Number of joint actions.
    #[must_use]
    pub fn n_joint_actions(&self) -> usize {
        match self {
            Self::Pointmass(p) => p.force_levels.len().pow(2 * p.agents as u32),
            Self::Khepera(k) => khepera::N_ACTIONS.pow(k.agents as u32),
            Self::Dcmotor(c) => c.actions.len(),
            Self::Pendulum(c) => c.actions.len(),
            Self::Carhill(c) => c.actions.len(),
            Self::Arm(c) => c.actions.len().pow(2),
        }
    }

    /// Checks the environment's parameters (building the model).
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.build().map(|_| ())
    }

    /// Builds the model (errors name the field).
    pub fn build(&self) -> Result<EnvModel, ConfigError> {
        Ok(match self {
            Self::Pointmass(p) => EnvModel::PointMass(PointMass::new(p.clone())?),
            Self::Khepera(k) => EnvModel::Khepera(KheperaModel::new(k.clone())?),
            Self::Dcmotor(c) => EnvModel::DcMotor(c.build()?),
            Self::Pendulum(c) => EnvModel::Pendulum(c.build()?),
            Self::Carhill(c) => EnvModel::CarHill(c.build()?),
            Self::Arm(c) => EnvModel::Arm(c.build()?),
        })
    }
}

impl<C: Clone> ClassicEnv<C> {
    /// The benchmark: the dynamics of `[env.model]` with the `actions` (errors name
    /// `env.*`).
    pub fn build<S: Benchmark<Config = C>>(&self) -> Result<Classic<S>, ConfigError> {
        let dynamics = S::new(self.model.clone())?;
        let table = dynamics.action_table("env.actions", &self.actions)?;
        Ok(Classic::from_table(dynamics, table))
    }
}

/// The fuzzy grid of the point-mass task: one list of cores for every position variable and
/// one for every velocity variable, or explicit cores per state variable.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GridConfig {
    /// Cores of every position variable (m; point masses and robots).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub position_cores: Vec<f64>,
    /// Cores of every velocity variable (m/s; point masses).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub velocity_cores: Vec<f64>,
    /// Heading cores of the Khepera robots: `heading_divisions + 1` cores evenly over
    /// `[-pi, pi]` (both ends are the same heading; the model wraps angles).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading_divisions: Option<usize>,
    /// Cores of each state variable, in state order; when given, they replace the two lists
    /// above (which must still be valid cores).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cores: Option<Vec<Vec<f64>>>,
    /// Membership functions on the cores: `"triangular"` (the fuzzy grid, default) or
    /// `"crisp"` (each state belongs to its nearest core alone: crisp grid Q-iteration over
    /// the same cores, the crisp control of the paper's Table 1).
    #[serde(default, skip_serializing_if = "is_triangular")]
    pub membership: Membership,
}

fn is_triangular(m: &Membership) -> bool {
    *m == Membership::Triangular
}

impl GridConfig {
    /// A grid given by the cores of each state variable (any grid, not only the point-mass
    /// layout). The two shared lists are filled from the first position and velocity variables
    /// (they are overridden by `cores` but must stay valid for the file to validate).
    #[must_use]
    pub fn explicit(cores: Vec<Vec<f64>>) -> Self {
        let pick = |i: usize| cores.get(i).or(cores.last()).cloned().unwrap_or_default();
        Self {
            position_cores: pick(0),
            velocity_cores: pick(2),
            heading_divisions: None,
            cores: Some(cores),
            membership: Membership::Triangular,
        }
    }
}

fn is_values(o: &IterationOperator) -> bool {
    *o == IterationOperator::Values
}

/// Solver settings as written in a config file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SolverSettings {
    /// Discount factor, `[0, 1)`.
    pub gamma: f64,
    /// Stopping threshold, `> 0`.
    pub xi: f64,
    /// Sweep limit, `>= 1`: every sweep counts, full backups and evaluation sweeps alike
    /// ([`SolverConfig::max_sweeps`]).
    pub max_sweeps: usize,
    /// Sweep order.
    pub sweep: SweepMode,
    /// Goal states are absorbing (zero future value).
    pub absorbing_goal: bool,
    /// Backup implementation.
    pub backup: BackupPath,
    /// Floating-point precision of the solver.
    pub precision: Precision,
    /// Extrapolate synchronous sweeps with MacQueen's bounds (see the solver docs).
    #[serde(default)]
    pub extrapolate: bool,
    /// Modified policy iteration: at most this many policy-evaluation sweeps after each full
    /// backup, 0 for value iteration (see [`fuzzyq_core::solver::Scheme`]).
    #[serde(default = "default_evaluation_sweeps")]
    pub evaluation_sweeps: usize,
    /// Modified policy iteration starts from the `V` of the grid with every other core,
    /// interpolated (see [`SolverConfig::coarse_start`]): the same error bound, fewer sweeps
    /// on fine grids. Default `false`; `true` in the Khepera robots' default configuration.
    #[serde(default, skip_serializing_if = "is_false")]
    pub coarse_start: bool,
    /// Force a kernel instance (`"scalar"`, `"portable"`, `"avx2"`, `"avx512"`); all give the same results.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kernel: Option<Kernel>,
    /// The iteration: `"values"` (default) interpolates the per-core maxima and keeps only
    /// `V` (`docs/design.md`, section 2; any grid size); `"q-values"` is Busoniu's fuzzy Q-iteration,
    /// as the ApproxRL toolbox runs it, maximising interpolated Q-values with `theta` stored
    /// (`cores x joint actions` values; synchronous, no extrapolation; see
    /// [`fuzzyq_core::solver::solve_q`]).
    #[serde(default, skip_serializing_if = "is_values")]
    pub operator: IterationOperator,
    /// Where the passes over `V` compute: `"cpu"` (default) or `"gpu"` (the block path in
    /// `f32` on a GPU through wgpu, the same policy bytes where the adapter fuses
    /// multiply-adds; see the `fuzzyq-gpu` crate).
    #[serde(default, skip_serializing_if = "is_cpu")]
    pub device: Device,
}

fn is_cpu(d: &Device) -> bool {
    *d == Device::Cpu
}

/// The default cap on evaluation sweeps per full backup.
pub const DEFAULT_EVALUATION_SWEEPS: usize = 5;

fn default_evaluation_sweeps() -> usize {
    DEFAULT_EVALUATION_SWEEPS
}

fn is_false(b: &bool) -> bool {
    !*b
}

impl Default for SolverSettings {
    fn default() -> Self {
        let c = SolverConfig::default();
        Self {
            gamma: c.gamma,
            xi: c.xi,
            max_sweeps: c.max_sweeps,
            sweep: c.sweep,
            absorbing_goal: c.absorbing_goal,
            backup: c.path,
            precision: Precision::F32,
            extrapolate: true,
            evaluation_sweeps: DEFAULT_EVALUATION_SWEEPS,
            coarse_start: false,
            kernel: None,
            operator: IterationOperator::Values,
            device: Device::Cpu,
        }
    }
}

/// The solver settings a user set, each `None` to keep the task's default: what the command
/// line's flags and Python's `solve` keywords carry. The defaults themselves are decided in
/// one place, [`TrainConfig::solver_defaults`]; [`apply`](Self::apply) sets what was given
/// over them, so that the command line and Python run the same settings for the same task.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SolverOverrides {
    /// Discount factor.
    pub gamma: Option<f64>,
    /// Stopping threshold.
    pub xi: Option<f64>,
    /// Sweep limit.
    pub max_sweeps: Option<usize>,
    /// Sweep order.
    pub sweep: Option<SweepMode>,
    /// Absorbing goal states.
    pub absorbing_goal: Option<bool>,
    /// Backup implementation.
    pub backup: Option<BackupPath>,
    /// Precision.
    pub precision: Option<Precision>,
    /// Extrapolation with MacQueen's bounds.
    pub extrapolate: Option<bool>,
    /// Evaluation sweeps per full backup.
    pub evaluation_sweeps: Option<usize>,
    /// A coarse start.
    pub coarse_start: Option<bool>,
    /// A kernel instance.
    pub kernel: Option<Kernel>,
    /// The iteration.
    pub operator: Option<IterationOperator>,
    /// Where the sweeps compute.
    pub device: Option<Device>,
}

impl SolverOverrides {
    /// Sets every given setting over `s`.
    pub fn apply(&self, s: &mut SolverSettings) {
        fn set<T: Clone>(to: &mut T, from: Option<&T>) {
            if let Some(v) = from {
                *to = v.clone();
            }
        }
        set(&mut s.gamma, self.gamma.as_ref());
        set(&mut s.xi, self.xi.as_ref());
        set(&mut s.max_sweeps, self.max_sweeps.as_ref());
        set(&mut s.sweep, self.sweep.as_ref());
        set(&mut s.absorbing_goal, self.absorbing_goal.as_ref());
        set(&mut s.backup, self.backup.as_ref());
        set(&mut s.precision, self.precision.as_ref());
        set(&mut s.extrapolate, self.extrapolate.as_ref());
        set(&mut s.evaluation_sweeps, self.evaluation_sweeps.as_ref());
        set(&mut s.coarse_start, self.coarse_start.as_ref());
        if self.kernel.is_some() {
            s.kernel = self.kernel;
        }
        set(&mut s.operator, self.operator.as_ref());
        set(&mut s.device, self.device.as_ref());
    }
}

impl SolverSettings {
    /// The core solver's configuration.
    #[must_use]
    pub fn solver_config(&self) -> SolverConfig {
        SolverConfig {
            gamma: self.gamma,
            xi: self.xi,
            max_sweeps: self.max_sweeps,
            sweep: self.sweep,
            absorbing_goal: self.absorbing_goal,
            path: self.backup,
            kernel: self.kernel,
            extrapolate: self.extrapolate,
            evaluation_sweeps: self.evaluation_sweeps,
            coarse_start: self.coarse_start,
        }
    }

    fn validate(&self) -> Result<(), ConfigError> {
        require!(
            !(self.operator == IterationOperator::QValues && self.sweep == SweepMode::Asynchronous),
            "solver.operator",
            "\"q-values\" runs synchronous sweeps; set sweep = \"sync\"",
        );
        require!(
            !(self.kernel.is_some() && self.operator == IterationOperator::QValues),
            "solver.kernel",
            "applies to the block backup of operator \"values\"; \"q-values\" has no kernel",
        );
        require!(
            !(self.kernel.is_some() && self.backup == BackupPath::Generic),
            "solver.kernel",
            "applies to the block backup; backup = \"generic\" has no kernel",
        );
        if self.device == Device::Gpu {
            require!(
                self.precision == Precision::F32,
                "solver.device",
                "\"gpu\" runs in f32; set solver.precision = \"f32\"",
            );
            require!(
                self.operator == IterationOperator::Values,
                "solver.device",
                "\"gpu\" runs operator \"values\"; \"q-values\" is CPU-only",
            );
            require!(
                self.sweep == SweepMode::Synchronous,
                "solver.device",
                "\"gpu\" runs synchronous sweeps; set solver.sweep = \"sync\"",
            );
            require!(
                self.kernel.is_none(),
                "solver.kernel",
                "chooses a CPU kernel; solver.device = \"gpu\" has none",
            );
        }
        discount("solver.gamma", self.gamma)?;
        positive("solver.xi", self.xi)?;
        require!(
            self.max_sweeps != 0,
            "solver.max_sweeps",
            "must be at least 1",
        );
        Ok(())
    }
}

impl Default for TrainConfig {
    /// The paper's point-mass task.
    fn default() -> Self {
        Self {
            env: EnvConfig::Pointmass(PointMassConfig::default()),
            grid: GridConfig {
                position_cores: paper::POSITION_CORES.to_vec(),
                velocity_cores: paper::VELOCITY_CORES.to_vec(),
                heading_divisions: None,
                cores: None,
                membership: Membership::Triangular,
            },
            solver: SolverSettings::default(),
        }
    }
}

impl TrainConfig {
    /// The default configuration of environment `env`: the paper's task for the point masses
    /// and the robots, the default preset for a classic benchmark.
    pub fn default_for(env: EnvKind) -> Result<Self, ConfigError> {
        match (env, env.spec().default_preset) {
            (EnvKind::Pointmass, _) => Ok(Self::default()),
            (EnvKind::Khepera, _) => Self::from_toml(DEFAULT_KHEPERA_TOML),
            (_, Some(preset)) => Self::from_preset(env, preset),
            (_, None) => Err(env.unknown_preset("")),
        }
    }

    /// A classic benchmark with the named preset's grid, actions, `gamma` and `xi`, the
    /// classic model parameters, and the toolbox's iteration (synchronous plain sweeps, at
    /// most 1000, in `f64`).
    pub fn from_preset(env: EnvKind, preset: &str) -> Result<Self, ConfigError> {
        fn with<S: Benchmark>(
            name: &str,
            wrap: fn(ClassicEnv<S::Config>) -> EnvConfig,
        ) -> Result<(classic::Preset, EnvConfig), ConfigError> {
            let p = classic::preset::<S>(name)?;
            let env = wrap(ClassicEnv {
                actions: p.actions.clone(),
                model: S::Config::default(),
            });
            Ok((p, env))
        }
        let (p, env) = match env {
            EnvKind::Dcmotor => with::<DcMotor>(preset, EnvConfig::Dcmotor)?,
            EnvKind::Pendulum => with::<Pendulum>(preset, EnvConfig::Pendulum)?,
            EnvKind::Carhill => with::<CarHill>(preset, EnvConfig::Carhill)?,
            EnvKind::Arm => with::<Arm>(preset, EnvConfig::Arm)?,
            EnvKind::Pointmass | EnvKind::Khepera => return Err(env.unknown_preset(preset)),
        };
        let mut grid = GridConfig::explicit(p.cores);
        grid.position_cores.clear();
        grid.velocity_cores.clear();
        let c = Self {
            env,
            grid,
            solver: SolverSettings {
                gamma: p.gamma,
                xi: p.xi,
                extrapolate: false,
                evaluation_sweeps: 0,
                precision: Precision::F64,
                ..SolverSettings::default()
            },
        };
        c.validate()?;
        Ok(c)
    }

    /// The default solver settings of a task, decided here once for the command line and
    /// Python alike: the paper's settings (modified policy iteration in `f32`) for the point
    /// masses, the same with a coarse start and the paper's threshold for the Khepera robots,
    /// and a classic benchmark's `preset` (its default one if `None`): the preset's `gamma`
    /// and `xi` with the toolbox's plain sweeps in `f64`.
    pub fn solver_defaults(
        env: EnvKind,
        preset: Option<&str>,
    ) -> Result<SolverSettings, ConfigError> {
        Ok(match (env, preset) {
            (_, Some(p)) => Self::from_preset(env, p)?.solver,
            (_, None) => Self::default_for(env)?.solver,
        })
    }

    /// The configuration of a task: its model, its grid, and its
    /// [default solver settings](Self::solver_defaults) with `overrides` set over them,
    /// validated.
    pub fn for_task(
        env: EnvConfig,
        grid: GridConfig,
        preset: Option<&str>,
        overrides: &SolverOverrides,
    ) -> Result<Self, ConfigError> {
        let mut solver = Self::solver_defaults(env.kind(), preset)?;
        overrides.apply(&mut solver);
        let c = Self { env, grid, solver };
        c.validate()?;
        Ok(c)
    }

    /// The configuration `fuzzyq config` prints: the commented default TOML of the point
    /// masses or the robots, or a classic benchmark's preset (the default one if `preset` is
    /// `None`) with a header saying how to use it.
    pub fn default_toml(env: EnvKind, preset: Option<&str>) -> Result<String, ConfigError> {
        match (env, env.spec().default_preset) {
            (EnvKind::Pointmass, _) if preset.is_none() => Ok(DEFAULT_POINTMASS_TOML.into()),
            (EnvKind::Khepera, _) if preset.is_none() => Ok(DEFAULT_KHEPERA_TOML.into()),
            (_, Some(default)) => {
                let name = preset.unwrap_or(default);
                let c = Self::from_preset(env, name)?;
                Ok(format!(
                    "# fuzzyq training configuration: {env}, preset \"{name}\".\n\
                     # Edit and pass back with `fuzzyq train --env {env} --config FILE.toml`.\n\n{}",
                    c.to_toml()
                ))
            }
            (_, None) => Err(env.unknown_preset(preset.unwrap_or_default())),
        }
    }

    /// Builds the model.
    pub fn build_model(&self) -> Result<EnvModel, SimError> {
        Ok(self.env.build()?)
    }

    /// The grid in precision `T`.
    pub fn grid<T: Real>(&self) -> Result<Grid<T>, SimError> {
        let cores = self
            .grid_cores()
            .into_iter()
            .map(|c| c.into_iter().map(T::from_f64).collect())
            .collect();
        Ok(Grid::new(cores)?.with_membership(self.grid.membership))
    }

    /// Number of joint actions.
    #[must_use]
    pub fn n_joint_actions(&self) -> usize {
        self.env.n_joint_actions()
    }
}

/// The default number of heading divisions of the Khepera grid.
pub const DEFAULT_HEADING_DIVISIONS: usize = 16;

fn check_cores(field: &str, cores: &[f64]) -> Result<(), ConfigError> {
    crate::error::single_precision(field, cores)?;
    Partition::try_from_cores(cores)
        .map(|_| ())
        .map_err(|e| ConfigError::invalid(field, e.to_string()))
}

impl TrainConfig {
    /// Parses and validates a TOML document. Errors are one line naming the field and, where
    /// the document has it, its line: `env.mass: invalid type: string "a", expected f64 (line
    /// 7)`, `env.mass: must be a positive number, got -1 (line 7)`.
    pub fn from_toml(text: &str) -> Result<Self, ConfigError> {
        let doc = TomlDoc::parse(text)?;
        let c: Self = doc.deserialize().map_err(|e| {
            // `[env]` is an internally tagged enum, which serde reads from a copy without
            // positions: its errors point at the section. Read the section again as its
            // kind's own type, with positions, to point at the field.
            if e.within("env") {
                env_error(&doc).unwrap_or(e)
            } else {
                e
            }
        })?;
        c.validate()
            .map_err(|e| doc.locate(e, &["", "env.", "grid.", "solver."]))?;
        Ok(c)
    }

    /// The configuration as TOML.
    pub fn to_toml(&self) -> String {
        toml::to_string(self).expect("a config always serialises")
    }

    /// Checks every field.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.env.validate()?;
        match &self.env {
            EnvConfig::Pointmass(p) => {
                check_cores("grid.velocity_cores", &self.grid.velocity_cores)?;
                require!(
                    p.reward == RewardShape::Paper || p.shaping_discount == self.solver.gamma,
                    "env.shaping_discount",
                    format!(
                        "is {} but solver.gamma is {}: the shaped reward keeps the optimal \
                         policy only with the learner's discount (set both alike)",
                        p.shaping_discount, self.solver.gamma
                    ),
                );
                require!(
                    self.grid.heading_divisions.is_none(),
                    "grid.heading_divisions",
                    "applies to the khepera environment only",
                );
            }
            EnvConfig::Khepera(_) => {
                if let Some(d) = self.grid.heading_divisions
                    && !(2..=360).contains(&d)
                {
                    return Err(ConfigError::invalid(
                        "grid.heading_divisions",
                        format!("must be between 2 and 360, got {d}"),
                    ));
                }
            }
            _ => {}
        }
        if self.env.is_classic() {
            require!(
                self.grid.cores.is_some(),
                "grid.cores",
                format!(
                    "the {} environment needs its cores given per state variable",
                    self.env.name()
                ),
            );
            require!(
                self.grid.heading_divisions.is_none(),
                "grid.heading_divisions",
                "applies to the khepera environment only",
            );
        } else {
            check_cores("grid.position_cores", &self.grid.position_cores)?;
        }
        if let Some(cores) = &self.grid.cores {
            let want = self.env.state_dim();
            require!(
                cores.len() == want,
                "grid.cores",
                format!(
                    "needs one list per state variable ({want}), got {}",
                    cores.len()
                ),
            );
            for (i, c) in cores.iter().enumerate() {
                check_cores(&format!("grid.cores[{i}]"), c)?;
            }
        }
        let n = self
            .grid_cores()
            .iter()
            .map(Vec::len)
            .try_fold(1usize, usize::checked_mul);
        require!(
            n.is_some(),
            "grid",
            "the joint grid has more cores than this machine can index",
        );
        self.solver.validate()
    }

    /// The cores of every state variable, in state order.
    #[must_use]
    pub fn grid_cores(&self) -> Vec<Vec<f64>> {
        if let Some(cores) = &self.grid.cores {
            return cores.clone();
        }
        match &self.env {
            EnvConfig::Pointmass(p) => (0..p.agents)
                .flat_map(|_| {
                    [
                        self.grid.position_cores.clone(),
                        self.grid.position_cores.clone(),
                        self.grid.velocity_cores.clone(),
                        self.grid.velocity_cores.clone(),
                    ]
                })
                .collect(),
            EnvConfig::Dcmotor(_)
            | EnvConfig::Pendulum(_)
            | EnvConfig::Carhill(_)
            | EnvConfig::Arm(_) => Vec::new(),
            EnvConfig::Khepera(k) => {
                let d = self
                    .grid
                    .heading_divisions
                    .unwrap_or(DEFAULT_HEADING_DIVISIONS);
                let pi = std::f64::consts::PI;
                let heading: Vec<f64> = (0..=d)
                    .map(|i| {
                        if i == d {
                            pi
                        } else {
                            -pi + 2.0 * pi * i as f64 / d as f64
                        }
                    })
                    .collect();
                (0..k.agents)
                    .flat_map(|_| {
                        [
                            self.grid.position_cores.clone(),
                            self.grid.position_cores.clone(),
                            heading.clone(),
                        ]
                    })
                    .collect()
            }
        }
    }

    /// Number of joint cores.
    #[must_use]
    pub fn n_cores(&self) -> usize {
        self.grid_cores().iter().map(Vec::len).product()
    }
}

/// The error of an `[env]` section read as its kind's own type (with positions), if that
/// type refuses it.
fn env_error(doc: &TomlDoc<'_>) -> Option<TomlError> {
    let env = doc.root.get_ref().get("env")?;
    let DeValue::Table(table) = env.get_ref() else {
        return None;
    };
    let kind = table.get("kind")?.get_ref().as_str()?.to_string();
    let mut table = table.clone();
    table.remove("kind");
    let table = Spanned::new(env.span(), table);
    let probe = |r: Result<(), TomlError>| r.err();
    match kind.as_str() {
        "pointmass" => probe(doc.deserialize_table::<PointMassConfig>(table).map(drop)),
        "khepera" => probe(doc.deserialize_table::<KheperaConfig>(table).map(drop)),
        "dcmotor" => probe(
            doc.deserialize_table::<ClassicEnv<DcMotorConfig>>(table)
                .map(drop),
        ),
        "pendulum" => probe(
            doc.deserialize_table::<ClassicEnv<PendulumConfig>>(table)
                .map(drop),
        ),
        "carhill" => probe(
            doc.deserialize_table::<ClassicEnv<CarHillConfig>>(table)
                .map(drop),
        ),
        "arm" => probe(
            doc.deserialize_table::<ClassicEnv<ArmConfig>>(table)
                .map(drop),
        ),
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_toml_is_the_default_config() {
        let c = TrainConfig::from_toml(DEFAULT_POINTMASS_TOML).unwrap();
        assert_eq!(c, TrainConfig::default());
        assert_eq!(c.n_cores(), 4_100_625);
        assert_eq!((c.solver.gamma, c.solver.xi), (paper::GAMMA, paper::XI));
        let again = TrainConfig::from_toml(&c.to_toml()).unwrap();
        assert_eq!(again, c);
    }

    #[test]
    fn default_khepera_toml_round_trips() {
        let c = TrainConfig::default_for(EnvKind::Khepera).unwrap();
        let EnvConfig::Khepera(k) = &c.env else {
            panic!("not khepera")
        };
        assert_eq!(k, &KheperaConfig::default());
        assert_eq!(c.n_cores(), (19 * 19 * 17usize).pow(2));
        assert_eq!(
            (c.solver.gamma, c.solver.xi),
            (paper::GAMMA, paper::KHEPERA_XI)
        );
        let cores = c.grid_cores();
        assert_eq!(cores[2].first(), Some(&-std::f64::consts::PI));
        assert_eq!(cores[2].last(), Some(&std::f64::consts::PI));
        assert_eq!(TrainConfig::from_toml(&c.to_toml()).unwrap(), c);
        assert!(EnvKind::parse("boat").is_err());
    }

    #[test]
    fn errors_name_the_field() {
        let e = TrainConfig::from_toml(&DEFAULT_POINTMASS_TOML.replace("mass = 0.5", "mass = -1"))
            .unwrap_err();
        assert_eq!(
            e.to_string(),
            "env.mass: must be a positive number, got -1 (line 7)"
        );
        let e =
            TrainConfig::from_toml(&DEFAULT_POINTMASS_TOML.replace("gamma = 0.96", "gamma = 1"))
                .unwrap_err();
        assert!(e.to_string().starts_with("solver.gamma"), "{e}");
        let e = TrainConfig::from_toml(&DEFAULT_POINTMASS_TOML.replace("xi = 0.05", "xii = 0.05"))
            .unwrap_err();
        assert!(e.to_string().contains("xii"), "{e}");
        assert!(!e.to_string().contains('\n'));
        let e = TrainConfig::from_toml(&DEFAULT_POINTMASS_TOML.replace(
            "velocity_cores = [-3.0, -1.0, 0.0, 1.0, 3.0]",
            "velocity_cores = [-3.0, 1.0, 0.0]",
        ))
        .unwrap_err();
        assert!(e.to_string().starts_with("grid.velocity_cores"), "{e}");
        // The shaped reward keeps the optimal policy only with the learner's discount.
        let shaped = DEFAULT_POINTMASS_TOML
            .replace("reward = \"paper\"", "reward = \"shaped\"")
            .replace("gamma = 0.96", "gamma = 0.9");
        let e = TrainConfig::from_toml(&shaped).unwrap_err();
        assert!(e.to_string().starts_with("env.shaping_discount"), "{e}");
        let both = shaped.replace("shaping_discount = 0.96", "shaping_discount = 0.9");
        assert!(TrainConfig::from_toml(&both).is_ok());
        let e = TrainConfig::from_toml(
            &DEFAULT_POINTMASS_TOML.replace("reward = \"paper\"", "reward = \"dense\""),
        )
        .unwrap_err();
        assert!(e.to_string().starts_with("env.reward"), "{e}");
    }

    /// Errors inside `[env...]` sections name the field and its line, not the section's
    /// first line (serde reads `[env]`, an internally tagged enum, from a copy without
    /// positions).
    #[test]
    fn errors_in_env_sections_point_at_the_field() {
        let pm = |from: &str, to: &str| {
            assert!(DEFAULT_POINTMASS_TOML.contains(from), "{from}");
            TrainConfig::from_toml(&DEFAULT_POINTMASS_TOML.replacen(from, to, 1))
                .unwrap_err()
                .to_string()
        };
        assert_eq!(
            pm("mass = 0.5", "mass = \"heavy\""),
            "env.mass: invalid type: string \"heavy\", expected f64 (line 7)"
        );
        let e = pm("mass = 0.5", "masss = 0.5");
        assert!(
            e.starts_with("env.masss: unknown field `masss`") && e.ends_with("(line 7)"),
            "{e}"
        );
        let e = pm("agents = 2 ", "agents = -2 ");
        assert!(
            e.starts_with("env.agents: ") && e.ends_with("(line 6)"),
            "{e}"
        );
        let e = pm("rk4_substeps = 10", "rk4_substeps = true");
        assert!(
            e.contains("env.rk4_substeps") && e.ends_with("(line 15)"),
            "{e}"
        );
        // [env.friction] is itself an internally tagged enum.
        let e = pm("eta = 1.0", "eta = \"x\"");
        assert!(
            e.contains("env.friction.eta") && e.ends_with("(line 22)"),
            "{e}"
        );
        let e = pm("eta = 1.0", "etaa = 1.0");
        assert!(e.contains("etaa") && e.ends_with("(line 22)"), "{e}");
        // Outside [env], as before.
        let e = pm("xi = 0.05", "xi = \"small\"");
        assert!(
            e.starts_with("solver.xi: invalid type") && e.ends_with("(line 32)"),
            "{e}"
        );
        // Validation errors name the line too.
        let e = pm("sample_time = 0.4", "sample_time = -0.4");
        assert_eq!(
            e,
            "env.sample_time: must be a positive number, got -0.4 (line 8)"
        );
        // Syntax errors name the line and the key.
        let e = pm("mass = 0.5", "mass = 0.5.1");
        assert!(e.starts_with("mass: ") && e.ends_with("(line 7)"), "{e}");
        let k = |from: &str, to: &str| {
            assert!(DEFAULT_KHEPERA_TOML.contains(from), "{from}");
            TrainConfig::from_toml(&DEFAULT_KHEPERA_TOML.replacen(from, to, 1))
                .unwrap_err()
                .to_string()
        };
        let e = k("sonar_std = 0.0", "sonar_std = \"loud\"");
        assert!(
            e.contains("env.noise.sonar_std") && e.ends_with("(line 35)"),
            "{e}"
        );
        let e = k("rays_per_sonar = 3", "rays_per_sonar = 3.5");
        assert!(
            e.contains("env.rays_per_sonar") && e.ends_with("(line 19)"),
            "{e}"
        );
    }

    /// An array longer than the field takes is refused (toml would read `[-6, 0, 6]` as
    /// `[-6, 0]`), naming the field, the values and the line.
    #[test]
    fn extra_values_are_refused() {
        let e = TrainConfig::from_toml(&DEFAULT_KHEPERA_TOML.replacen(
            "x = [-6.0, 6.0]",
            "x = [-6, 0, 6]",
            1,
        ))
        .unwrap_err()
        .to_string();
        assert_eq!(
            e,
            "env.arena.x: has 3 values ([-6, 0, 6]), expected 2 (line 26)"
        );
        let e = TrainConfig::from_toml(&DEFAULT_KHEPERA_TOML.replacen(
            "sonar_levels = [0.5, 1.0]",
            "sonar_levels = [0.5, 1.0, 1.5]",
            1,
        ))
        .unwrap_err()
        .to_string();
        assert!(e.starts_with("env.sonar_levels: has 3 values"), "{e}");
    }

    #[test]
    fn toml_errors_are_one_line() {
        for text in [
            "\"a\nb\" = 1",
            "[env]\nkind = \"pointmass\"\n\"x\\ny\" = 1",
            "[env]\nkind = \"x\\ny\"",
            "a = \"\u{7}\"\n",
            &format!("[env]\nkind = \"{}\"", "z".repeat(10_000)),
        ] {
            let e = TrainConfig::from_toml(text).unwrap_err().to_string();
            assert!(!e.contains('\n') && e.len() < 600, "{e:?}");
        }
    }
}
