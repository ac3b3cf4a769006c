//! Why a GPU run was refused or failed.

use fuzzyq_core::solver::SolveError;

/// An error of the GPU path: no adapter, a problem it cannot hold or run, a device failure,
/// or the solver's own error.
#[derive(Clone, Debug, thiserror::Error)]
pub enum GpuError {
    /// No GPU adapter was found (no Vulkan, Metal or DX12 driver, or none that wgpu accepts).
    #[error("no GPU adapter found (wgpu found no Vulkan, Metal or DX12 device{hint})")]
    NoAdapter {
        /// What to try, for this platform.
        hint: &'static str,
    },
    /// `FUZZYQ_GPU_ADAPTER` names no adapter.
    #[error("FUZZYQ_GPU_ADAPTER={want} names no GPU adapter (found: {found})")]
    NoNamedAdapter {
        /// The name asked for.
        want: String,
        /// The adapters found.
        found: String,
    },
    /// A `FUZZYQ_GPU_*` environment variable holds a value its setting does not take.
    #[error("{name}={value} is not a setting of the GPU path: it takes {expected}")]
    Setting {
        /// The variable.
        name: &'static str,
        /// Its value.
        value: String,
        /// What it takes, in words.
        expected: &'static str,
    },
    /// The adapter refused the device the solver asks for.
    #[error("the GPU adapter {adapter} refused a device: {}", one_line(why))]
    Device {
        /// The adapter's name.
        adapter: String,
        /// wgpu's message.
        why: String,
    },
    /// The run needs what the GPU path does not do.
    #[error("the GPU path {0}; run it with --device cpu")]
    Unsupported(&'static str),
    /// A buffer exceeds the adapter's limits.
    #[error(
        "{what} needs {need} bytes on the GPU, more than the adapter's limit of {limit} bytes for one {kind}"
    )]
    TooLarge {
        /// Which buffer.
        what: &'static str,
        /// Bytes it needs.
        need: u64,
        /// The adapter's limit.
        limit: u64,
        /// Which limit (a buffer, a binding).
        kind: &'static str,
    },
    /// `V` needs more parts (of one storage binding each) than a kernel may bind.
    #[error(
        "V in {parts} parts of one storage binding each needs more than the {limit} parts \
         a kernel of this adapter may bind"
    )]
    TooManyParts {
        /// The parts of `V`.
        parts: usize,
        /// The most parts a kernel may bind (the adapter's storage buffers per kernel, less
        /// the ten every kernel binds).
        limit: u64,
    },
    /// The run's buffers would take more device memory than the adapter has (estimated
    /// before allocating).
    #[error(
        "the run needs {:.2} GB of GPU memory ({what}), more than the {:.2} GB the adapter has \
         free; run it on a smaller grid or with --device cpu",
        *.need as f64 / 1e9, *.available as f64 / 1e9
    )]
    OutOfMemory {
        /// What takes the memory, in words.
        what: String,
        /// Bytes the run's buffers take.
        need: u64,
        /// Bytes the adapter has for them.
        available: u64,
    },
    /// The device ran out of memory or lost itself.
    #[error("the GPU failed: {}", one_line(.0))]
    Failed(String),
    /// The solver's own error (a model, grid or configuration it refuses, or an interrupted run).
    #[error(transparent)]
    Solve(#[from] SolveError),
}

impl GpuError {
    /// [`GpuError::TooLarge`] for `what`, which needs `need` bytes of one storage binding of at
    /// most `limit`.
    pub(crate) fn over_binding(what: &'static str, need: u64, limit: u64) -> Self {
        Self::TooLarge {
            what,
            need,
            limit,
            kind: "storage binding",
        }
    }
}

/// wgpu's multi-line messages on one line: their non-empty lines, trimmed, joined by "; ".
fn one_line(s: &str) -> String {
    s.lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect::<Vec<_>>()
        .join("; ")
}

#[cfg(test)]
mod tests {
    #[test]
    fn device_failures_print_on_one_line() {
        let e = super::GpuError::Failed("Validation Error\n\nCaused by:\n  In x\n".into());
        assert_eq!(
            e.to_string(),
            "the GPU failed: Validation Error; Caused by:; In x"
        );
    }
}
