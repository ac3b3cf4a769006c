//! The device a [`crate::Gpu`] holds, and what was measured of it: the lowest layer above
//! the errors, which the buffers, the kernels and the probes build on.

use crate::error::GpuError;

/// What a GPU is, as the solver sees it.
#[derive(Clone, Debug, PartialEq)]
pub struct AdapterSummary {
    /// The adapter's name (`"NVIDIA H200"`, `"llvmpipe (LLVM 15.0.6, 256 bits)"`).
    pub name: String,
    /// The graphics API wgpu drives it through (`"vulkan"`, `"metal"`, `"dx12"`).
    pub backend: String,
    /// The driver and its version, as the adapter reports them.
    pub driver: String,
    /// Whether the adapter's `fma` is fused (one rounding), measured at start-up: where it is,
    /// the GPU gives the CPU kernels' bits; where it is not (Mesa's lavapipe), it gives the
    /// bits of the same sums with every product rounded first
    /// ([`crate::reference::Rounding::Product`]).
    pub fused_fma: bool,
    /// Whether the adapter has `f64` in shaders (the change statistics run on the GPU with it,
    /// on the host from the values without it).
    pub f64: bool,
    /// The adapter's largest buffer, in bytes.
    pub max_buffer: u64,
    /// The adapter's largest storage-buffer binding, in bytes.
    pub max_binding: u64,
    /// Storage buffers one kernel may bind (ten, plus one per part of a `V` larger than a
    /// binding).
    pub max_storage_buffers: u32,
    /// The adapter's memory for a run's buffers, in bytes, as the driver reported it when
    /// the GPU was opened: on Vulkan, its budget for the largest device-local heap
    /// (`VK_EXT_memory_budget`: what this process may still allocate) or else that heap's
    /// size; `None` where the API does not say (Metal, DX12).
    pub memory: Option<u64>,
    /// The adapter's subgroup size, where it has subgroup operations, one size, and a
    /// workgroup of that many threads is one subgroup whose shuffles reduce as the last stage
    /// needs (checked at start-up); the last stage then reduces a core's lanes with them.
    pub subgroup_size: Option<u32>,
    /// Whether the adapter is software on the host's CPU (wgpu's `DeviceType::Cpu`: Mesa's
    /// lavapipe, WARP); the kernels' defaults differ: the rows compiled in for every problem
    /// ([`crate::Gpu::with_rows_compiled_in_from`]), and where they are too large, the last
    /// stage merged.
    pub software: bool,
    /// Where the time to open the GPU went.
    pub opening: OpeningSeconds,
}

/// Where the time to open a GPU went ([`AdapterSummary::opening`]), in seconds: on a short
/// run (the paper's point masses) the open is on the critical path.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct OpeningSeconds {
    /// wgpu's instance, the adapters listed and the device requested.
    pub device: f64,
    /// The generic kernels compiled.
    pub kernels: f64,
    /// The start-up probes: is `fma` fused, do subgroup shuffles reduce as needed.
    pub probes: f64,
}

/// wgpu's device and queue, the adapter's summary, and the runtime checks its kernels are
/// compiled with.
pub(crate) struct Context {
    pub(crate) device: wgpu::Device,
    pub(crate) queue: wgpu::Queue,
    pub(crate) summary: AdapterSummary,
    pub(crate) checks: Checks,
}

/// Which of wgpu's runtime checks the kernels are compiled with (`FUZZYQ_GPU_CHECKS`:
/// `all`, `none`, or a list of `zero`, `loops`, `division`, `bounds` joined by `,`).
/// wgpu adds them to every kernel for code it cannot trust; these kernels index only within
/// their buffers and arrays, bound every loop by a count, divide only by nonzero values and
/// read workgroup memory only where they wrote it first (the crate docs, "Runtime checks"),
/// so none of them changes a result: they cost instructions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Checks {
    /// Workgroup memory zeroed before each workgroup starts (`zero`).
    pub zero_workgroup: bool,
    /// A 64-bit counter on every loop that stops it after 2^64 iterations (`loops`).
    pub loops: bool,
    /// Integer division and remainder guarded against a zero divisor (`division`).
    pub division: bool,
    /// Indices into arrays and buffers clamped to their length (`bounds`; buffers only
    /// where the driver does not bound them itself).
    pub bounds: bool,
}

impl Checks {
    /// Every check wgpu adds by default.
    pub const ALL: Checks = Checks {
        zero_workgroup: true,
        loops: true,
        division: true,
        bounds: true,
    };
    /// None of them.
    pub const NONE: Checks = Checks {
        zero_workgroup: false,
        loops: false,
        division: false,
        bounds: false,
    };

    /// `all`, `none`, or checks named by `zero`, `loops`, `division` and `bounds` joined by
    /// `,` (`None` for anything else).
    #[must_use]
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "all" => return Some(Self::ALL),
            "none" => return Some(Self::NONE),
            _ => {}
        }
        let mut c = Self::NONE;
        for name in s.split(',') {
            let check = match name.trim() {
                "zero" => &mut c.zero_workgroup,
                "loops" => &mut c.loops,
                "division" => &mut c.division,
                "bounds" => &mut c.bounds,
                _ => return None,
            };
            *check = true;
        }
        Some(c)
    }
}

/// `all`, `none` or the checks' names joined by `,`, as [`Checks::parse`] reads them.
impl core::fmt::Display for Checks {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match *self {
            Self::ALL => return f.write_str("all"),
            Self::NONE => return f.write_str("none"),
            _ => {}
        }
        let names = [
            (self.zero_workgroup, "zero"),
            (self.loops, "loops"),
            (self.division, "division"),
            (self.bounds, "bounds"),
        ];
        let on: Vec<&str> = names.iter().filter(|n| n.0).map(|n| n.1).collect();
        f.write_str(&on.join(","))
    }
}

/// The adapter named by `FUZZYQ_GPU_ADAPTER` (a part of its name), else the first of the
/// most capable kind: a discrete GPU, then an integrated one, a virtual one, a CPU (Mesa's
/// lavapipe).
pub(crate) fn pick_adapter(instance: &wgpu::Instance) -> Result<wgpu::Adapter, GpuError> {
    let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    let rank = |t: wgpu::DeviceType| match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    };
    if let Ok(want) = std::env::var("FUZZYQ_GPU_ADAPTER") {
        let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
        return adapters
            .into_iter()
            .find(|a| {
                a.get_info()
                    .name
                    .to_lowercase()
                    .contains(&want.to_lowercase())
            })
            .ok_or(GpuError::NoNamedAdapter {
                want,
                found: names.join(", "),
            });
    }
    adapters
        .into_iter()
        .min_by_key(|a| rank(a.get_info().device_type))
        .ok_or(GpuError::NoAdapter {
            hint: if cfg!(target_os = "linux") {
                "; on Linux install the Vulkan loader and a driver, e.g. `apt-get install \
                 libvulkan1 mesa-vulkan-drivers`"
            } else {
                ""
            },
        })
}
