//! Contacts between the discs and what they touch: who, when, and the running count.

use serde::{Deserialize, Serialize};

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
