//! Memory estimates: the large buffers a run will allocate, computed from its sizes before
//! anything is allocated, and the limit they must fit in ([`Limit`]), so that a grid of a
//! billion cores or a rollout of four billion steps is refused with its estimate instead of
//! aborting or swapping the machine to a halt.
//!
//! The estimates count the buffers that grow with the problem (per-core vectors, tables, one
//! record per step or start) and ignore what is small and fixed; they are within a few
//! percent of the peak resident memory of the runs that matter (the paper's grid: 4.1 million
//! cores).

use fuzzyq_core::solver::{Device, IterationOperator, Precision};

use crate::error::SimError;
use crate::io::config::TrainConfig;

/// The memory a run needs, roughly, and what needs it.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// Bytes.
    pub bytes: f64,
    /// What needs them (`"4.1e6 cores x 625 joint actions of the q-values operator"`).
    pub what: String,
}

/// The most memory a run may take.
#[derive(Clone, Debug, PartialEq)]
pub struct Limit {
    /// Bytes.
    pub bytes: f64,
    /// Where the limit comes from, for messages (`"90% of this machine's 24.0 GB"`).
    pub source: String,
}

/// Bytes per GB (10^9, as `free -g` and most people count).
const GB: f64 = 1e9;

/// When the machine's memory cannot be read.
const FALLBACK_BYTES: f64 = 16.0 * GB;

impl Limit {
    /// `gb` gigabytes if given (a deliberate choice, any positive number), else 90% of the
    /// machine's physical memory (16 GB where the OS does not say).
    pub fn new(gb: Option<f64>) -> Result<Self, SimError> {
        if let Some(gb) = gb {
            if !(gb > 0.0 && gb.is_finite()) {
                return Err(crate::error::ConfigError::invalid(
                    "max_memory_gb",
                    format!("must be a positive number of GB, got {gb}"),
                )
                .into());
            }
            return Ok(Self {
                bytes: gb * GB,
                source: "as set".into(),
            });
        }
        Ok(match physical_memory() {
            Some(total) => Self {
                bytes: 0.9 * total,
                source: format!("90% of this machine's {:.1} GB", total / GB),
            },
            None => Self {
                bytes: FALLBACK_BYTES,
                source: "the default where the machine's memory is unknown".into(),
            },
        })
    }

    /// Refuses `estimate` if it exceeds the limit.
    pub fn check(&self, estimate: &Estimate) -> Result<(), SimError> {
        if estimate.bytes <= self.bytes {
            return Ok(());
        }
        Err(SimError::Memory {
            needed_gb: estimate.bytes / GB,
            limit_gb: self.bytes / GB,
            what: estimate.what.clone(),
            limit_source: self.source.clone(),
        })
    }
}

/// The machine's physical memory in bytes (Linux `/proc/meminfo`).
fn physical_memory() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = text.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0)
}

/// The estimate of training `config` with fuzzy Q-iteration (the learners from samples keep
/// per-agent parameters only, far smaller): per-core vectors of the value operator (three
/// `V`, the greedy actions, modified policy iteration's policy and pairs, the rewards and the
/// solution; the policy file is encoded as it is written), or the Q-values tables of
/// Busoniu's operator (two `theta`, the rewards and up to four successor memberships per core
/// and joint action).
#[must_use]
pub fn train(config: &TrainConfig) -> Estimate {
    let cores: f64 = config.grid_cores().iter().map(|c| c.len() as f64).product();
    let joint = joint_actions(config);
    let s: f64 = match config.solver.precision {
        Precision::F32 => 4.0,
        Precision::F64 => 8.0,
    };
    match config.solver.operator {
        // On the GPU the host holds the rewards (and goal flags), then the result read back a
        // piece at a time into grid order: `V` and the greedy actions, once each (the file is
        // encoded as it is written). A coarse start's `V`, interpolated and reordered for the
        // device, takes as much for a moment, and so does a checkpoint (`V` and the previous
        // `V` or the policy read back whole, written as encoded, before the result exists).
        IterationOperator::Values if config.solver.device == Device::Gpu => Estimate {
            bytes: cores * (4.0 + 1.0 + 4.0 + 4.0),
            what: format!("{cores:.3e} cores (V on the GPU; the rewards and the result here)"),
        },
        IterationOperator::Values => Estimate {
            // 3 V + greedy + solution (V, greedy) + MPI (policy, pairs) + rewards.
            bytes: cores * (3.0 * s + 4.0 + (s + 4.0) + 4.0 + 2.0 * s.max(4.0) + s),
            what: format!("{cores:.3e} cores"),
        },
        IterationOperator::QValues => {
            let pairs = cores * joint;
            Estimate {
                bytes: pairs * (2.0 * s + s + 4.0 * (4.0 + s) + 8.0) + cores * (s + 4.0) * 3.0,
                what: format!("{pairs:.3e} Q-values (the q-values operator stores them all)"),
            }
        }
    }
}

/// The estimate of `fuzzyq bench` on `config`'s grid: a training run's on the CPU ([`train`]);
/// on the GPU (`gpu`) the rewards and goal flags, and `V` and the greedy actions read back
/// once (`V` itself is on the device).
#[must_use]
pub fn bench(config: &TrainConfig, gpu: bool) -> Estimate {
    if !gpu {
        return train(config);
    }
    let cores: f64 = config.grid_cores().iter().map(|c| c.len() as f64).product();
    Estimate {
        bytes: cores * (4.0 + 1.0 + 4.0 + 4.0),
        what: format!("{cores:.3e} cores (V on the GPU; the rewards and V read back here)"),
    }
}

/// Joint actions of `config`'s task, as a float (no overflow for absurd agent counts).
fn joint_actions(config: &TrainConfig) -> f64 {
    use crate::io::config::EnvConfig;
    match &config.env {
        EnvConfig::Pointmass(p) => (p.force_levels.len() as f64).powi(2 * p.agents as i32),
        EnvConfig::Khepera(k) => (crate::model::khepera::N_ACTIONS as f64).powi(k.agents as i32),
        EnvConfig::Dcmotor(c) => c.actions.len() as f64,
        EnvConfig::Pendulum(c) => c.actions.len() as f64,
        EnvConfig::Carhill(c) => c.actions.len() as f64,
        EnvConfig::Arm(c) => (c.actions.len() as f64).powi(2),
    }
}

/// The estimate of `runs` rollouts of `steps` steps each keeping `per_step` bytes per step
/// (states, actions, rewards) and `per_run` bytes per run (its metrics).
#[must_use]
pub fn rollouts(runs: f64, steps: f64, per_step: f64, per_run: f64) -> Estimate {
    Estimate {
        bytes: runs * (steps * per_step + per_run),
        what: if runs > 1.0 {
            format!("{runs:.3e} runs of {steps:.3e} steps")
        } else {
            format!("a run of {steps:.3e} steps")
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn estimates_and_limits() {
        let paper = TrainConfig::default();
        let e = train(&paper);
        // The paper's grid: 4.1e6 cores, about 0.2 GB in single precision.
        assert!(e.bytes > 0.1 * GB && e.bytes < 0.3 * GB, "{e:?}");
        let limit = Limit::new(Some(0.05)).unwrap();
        let err = limit.check(&e).unwrap_err().to_string();
        assert!(
            err.contains("4.101e6 cores") && err.contains("0.05 GB"),
            "{err}"
        );
        let mut q = paper.clone();
        q.solver.operator = IterationOperator::QValues;
        let e = train(&q);
        assert!(e.bytes > 50.0 * GB, "{e:?}");
        assert!(Limit::new(Some(0.0)).is_err());
        assert!(Limit::new(Some(f64::NAN)).is_err());
        let machine = Limit::new(None).unwrap();
        assert!(machine.bytes > 0.0, "{machine:?}");
        assert!(
            machine
                .check(&rollouts(1.0, 4294967296.0, 100.0, 0.0))
                .is_err()
        );
        assert!(machine.check(&rollouts(1.0, 1000.0, 100.0, 0.0)).is_ok());
    }

    /// Three point masses on the paper's cores train on one H200 (141 GB) from its host's
    /// 128 GiB: the run holds the rewards and the result once, 13 bytes per core.
    #[test]
    fn the_papers_three_masses_fit_an_h200_host() {
        let mut three = TrainConfig::default();
        let crate::io::config::EnvConfig::Pointmass(p) = &mut three.env else {
            unreachable!("the default task")
        };
        p.agents = 3;
        three.solver.device = Device::Gpu;
        let e = train(&three);
        let host = Limit {
            bytes: 0.9 * 128.0 * f64::from(1u32 << 30),
            source: "90% of an H200 host's 128 GiB".into(),
        };
        assert!(host.check(&e).is_ok(), "{e:?}");
        assert!((e.bytes / 8.304e9 - 13.0).abs() < 0.01, "{e:?}");
    }
}
