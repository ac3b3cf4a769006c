//! The numbers fuzzyq takes from the paper (Luviano-Cruz et al. 2018), in one place.
//!
//! The code that reproduces the paper (the default grids and learners, the figures' starts,
//! Table 1) uses these constants; the default configuration files, written out as commented
//! TOML, are tested against them. `docs/design.md` explains how each is read.

/// The position cores of every agent and axis (section 3.1, figure 1), m.
pub const POSITION_CORES: [f64; 9] = [-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0];

/// The velocity cores of every agent and axis (section 3.1, figure 1), m/s.
pub const VELOCITY_CORES: [f64; 5] = [-3.0, -1.0, 0.0, 1.0, 3.0];

/// The force levels per axis (section 3.1); each agent's actions are their square, N.
pub const FORCE_LEVELS: [f64; 5] = [-2.0, -0.2, 0.0, 0.2, 2.0];

/// The discount factor of every experiment.
pub const GAMMA: f64 = 0.96;

/// The stopping threshold of the point-mass task (eq 21).
pub const XI: f64 = 0.05;

/// The stopping threshold of the robot experiment (section 3.3).
pub const KHEPERA_XI: f64 = 0.2;

/// The initial state of figures 2-4 (section 3.1): `[s_1x, s_1y, v_1x, v_1y, s_2x, ...]`.
pub const X0: [f64; 8] = [-4.0, -6.0, -2.0, 2.0, 5.0, 3.0, 2.0, -1.0];

/// The initial state of Table 1 (section 4): both agents at rest.
pub const TABLE1_X0: [f64; 8] = [-4.0, 5.0, 0.0, 0.0, 5.0, -3.0, 0.0, 0.0];

/// The initial state of the robot experiment (section 3.3), robots at rest.
pub const KHEPERA_X0: [f64; 8] = [-4.0, 5.0, 0.0, 0.0, 5.0, 3.0, 0.0, 0.0];

/// The paper's Table 1: `(metric, CMOMMT, fuzzy)`.
pub const TABLE1: [(&str, f64, f64); 3] = [
    ("final error (cm)", 18.0, 6.0),
    ("time to goal (s)", 25.0, 12.0),
    ("iterations", 34.0, 27.0),
];
