//! Exported policies: a fuzzy Q-iteration policy in the forms a `no_std` controller reads
//! without allocating: the grid, each agent's actions, the per-core greedy actions in the
//! smallest integer type that holds them, and optionally `V`, in the policy's precision.
//!
//! - [`export_bytes`]: the compact binary format that [`fuzzyq_core::view::PolicyView::parse`]
//!   checks and borrows in place (the format is specified there), for `include_bytes!` or
//!   flash memory; with [`ExportOptions::decisions`], also the block path's tables and the
//!   rewards, so that the view takes greedy decisions without the model;
//! - [`export_rust`]: a Rust module of `static` arrays whose `view()` builds the same
//!   [`fuzzyq_core::view::PolicyView`] with [`fuzzyq_core::view::PolicyView::from_parts`]
//!   (no parsing, no checksum; the compiler checks the types);
//! - [`ExportedBytes`]: an exported file read back for a controller with `std` (a robot
//!   computer running Linux), placed where a greedy decision reads it fastest.

use std::fmt::Write as _;
use std::path::Path;

use fuzzyq_core::solver::{BackupPath, DecisionTables, Operator};
use fuzzyq_core::view::{HEADER_LEN, MAGIC, VERSION, crc32, padding};
use fuzzyq_core::{Backup, Membership, Model, Real};

use crate::error::{PolicyFileError, SimError};
use crate::io::config::TrainConfig;
use crate::io::policy_file::{PolicyArtifact, Values};

/// What an exported policy holds besides its grid, actions and greedy actions.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExportOptions {
    /// `V` per core: the value at any state, and the greedy policy's `Q(x, .)`.
    pub values: bool,
    /// The decision tables (with `V`): the greedy policy without the model
    /// ([`DecisionTables`]; block-path models only).
    pub decisions: bool,
}

impl Default for ExportOptions {
    /// `V`, no decision tables.
    fn default() -> Self {
        Self {
            values: true,
            decisions: false,
        }
    }
}

/// The decision tables of `config`'s operator in precision `T` (the operator the greedy
/// rollout uses: the automatic backup path).
fn decision_tables<T: Real>(config: &TrainConfig) -> Result<DecisionTables<T>, SimError>
where
    crate::model::EnvModel: Model<T> + Sync,
{
    let model = config.build_model()?;
    let grid = config.grid::<T>()?;
    let backup = Backup {
        gamma: T::from_f64(config.solver.gamma),
        absorbing_goal: config.solver.absorbing_goal,
    };
    let op = Operator::new(&model, grid.view(), backup, BackupPath::Auto)?;
    Ok(op.decision_tables()?)
}

/// Little-endian bytes of `v`.
fn u32_bytes(v: impl IntoIterator<Item = u32>) -> Vec<u8> {
    v.into_iter().flat_map(u32::to_le_bytes).collect()
}

/// The little-endian bytes of `values`.
fn le_bytes<T: Copy, const N: usize>(values: &[T], le: fn(T) -> [u8; N]) -> Vec<u8> {
    values.iter().flat_map(|&x| le(x)).collect()
}

/// `v` (row-major over the grid's cores, `cores` per state variable) in the decision order of
/// `t`: row-major over the blocks' cores, the blocks in contraction order.
fn in_decision_order<T: Copy>(v: &[T], cores: &[Vec<f64>], t: &DecisionTables<T>) -> Vec<T> {
    let counts: Vec<usize> = cores.iter().map(Vec::len).collect();
    let mut strides = vec![0usize; counts.len()];
    let mut s = 1usize;
    for b in t.blocks.iter().rev() {
        for &d in b.dims.iter().rev() {
            strides[d as usize] = s;
            s *= counts[d as usize];
        }
    }
    let mut out = v.to_vec();
    let mut idx = vec![0usize; counts.len()];
    let mut j = 0usize;
    for &x in v {
        out[j] = x;
        // The next grid core, the last variable fastest.
        for d in (0..counts.len()).rev() {
            idx[d] += 1;
            j += strides[d];
            if idx[d] < counts[d] {
                break;
            }
            j -= idx[d] * strides[d];
            idx[d] = 0;
        }
    }
    out
}

/// The decision tables' sections (the format of `fuzzyq_core::view`'s `decide` module), values
/// written by `real`.
fn decision_sections<T: Real>(
    t: &DecisionTables<T>,
    real: &dyn Fn(f64) -> Vec<u8>,
    section: &mut dyn FnMut(&[u8]),
) {
    let reals = |v: &[T]| -> Vec<u8> { v.iter().flat_map(|x| real(x.to_f64())).collect() };
    section(&u32_bytes([t.blocks.len() as u32, 0]));
    section(&u32_bytes(t.blocks.iter().flat_map(|b| {
        [
            b.dims.len() as u32,
            b.n_actions,
            b.col.len() as u32,
            b.max_support,
        ]
    })));
    section(&u32_bytes(
        t.blocks.iter().flat_map(|b| b.dims.iter().copied()),
    ));
    section(&u32_bytes(t.q_index.iter().copied()));
    for b in &t.blocks {
        section(&u32_bytes(b.ptr.iter().copied()));
        section(&u32_bytes(b.col.iter().copied()));
        section(&reals(&b.weight));
    }
    section(&reals(&[t.gamma]));
    section(&reals(&t.rewards));
}

/// What both forms hold, gathered from a policy.
struct Parts<'p> {
    /// Each state variable's cores.
    cores: Vec<Vec<f64>>,
    /// Per agent: (actions, components per action, the actions' components action-major).
    sets: Vec<(usize, usize, Vec<f64>)>,
    /// Bytes per greedy action: 1, 2 or 4.
    greedy_bytes: u32,
    membership: Membership,
    artifact: &'p PolicyArtifact,
}

impl<'p> Parts<'p> {
    fn of(artifact: &'p PolicyArtifact) -> Result<Self, SimError> {
        let config = &artifact.config;
        let model = config.build_model()?;
        let n_agents = Model::<f64>::n_agents(&model);
        let sets: Vec<(usize, usize, Vec<f64>)> = (0..n_agents)
            .map(|i| {
                let s = Model::<f64>::action_set(&model, i);
                let values = (0..s.n_actions())
                    .flat_map(|a| s.action(a).to_vec())
                    .collect();
                (s.n_actions(), s.dim(), values)
            })
            .collect();
        let n_joint: usize = sets.iter().map(|s| s.0).product();
        let greedy_bytes: u32 = if n_joint <= 1 << 8 {
            1
        } else if n_joint <= 1 << 16 {
            2
        } else {
            4
        };
        Ok(Self {
            cores: config.grid_cores(),
            sets,
            greedy_bytes,
            membership: config.grid.membership,
            artifact,
        })
    }

    /// Bytes per value: 4 (`f32`) or 8 (`f64`).
    fn value_bytes(&self) -> u32 {
        match self.artifact.values {
            Values::F32(_) => 4,
            Values::F64(_) => 8,
        }
    }

    fn n_joint(&self) -> usize {
        self.sets.iter().map(|s| s.0).product()
    }
}

/// The bytes of `artifact` exported with what `options` asks for.
pub fn export_bytes(
    artifact: &PolicyArtifact,
    options: ExportOptions,
) -> Result<Vec<u8>, SimError> {
    let with_values = options.values;
    if options.decisions && !with_values {
        return Err(crate::error::ConfigError::invalid(
            "export",
            "the decision tables need V: export them with the values",
        )
        .into());
    }
    let parts = Parts::of(artifact)?;
    let value_bytes = parts.value_bytes();
    let real = |x: f64| -> Vec<u8> {
        if value_bytes == 4 {
            (x as f32).to_le_bytes().to_vec()
        } else {
            x.to_le_bytes().to_vec()
        }
    };
    let mut payload = Vec::new();
    let section = |payload: &mut Vec<u8>, bytes: &[u8]| {
        payload.extend_from_slice(bytes);
        payload.resize(payload.len() + padding(bytes.len()), 0);
    };
    let counts = u32_bytes(parts.cores.iter().map(|c| c.len() as u32));
    section(&mut payload, &counts);
    let shapes = u32_bytes(parts.sets.iter().flat_map(|s| [s.0 as u32, s.1 as u32]));
    section(&mut payload, &shapes);
    let core_values: Vec<u8> = parts
        .cores
        .iter()
        .flatten()
        .flat_map(|&x| real(x))
        .collect();
    section(&mut payload, &core_values);
    let action_values: Vec<u8> = parts
        .sets
        .iter()
        .flat_map(|s| &s.2)
        .flat_map(|&x| real(x))
        .collect();
    section(&mut payload, &action_values);
    let greedy: Vec<u8> = match parts.greedy_bytes {
        1 => artifact.greedy.iter().map(|&u| u as u8).collect(),
        2 => artifact
            .greedy
            .iter()
            .flat_map(|&u| (u as u16).to_le_bytes())
            .collect(),
        _ => u32_bytes(artifact.greedy.iter().copied()),
    };
    section(&mut payload, &greedy);
    if options.decisions {
        // `V` in the tables' decision order, then the tables.
        match &artifact.values {
            Values::F32(v) => {
                let t = decision_tables::<f32>(&artifact.config)?;
                let v = in_decision_order(v, &parts.cores, &t);
                section(&mut payload, le_bytes(&v, f32::to_le_bytes).as_slice());
                decision_sections(&t, &real, &mut |b| section(&mut payload, b));
            }
            Values::F64(v) => {
                let t = decision_tables::<f64>(&artifact.config)?;
                let v = in_decision_order(v, &parts.cores, &t);
                section(&mut payload, le_bytes(&v, f64::to_le_bytes).as_slice());
                decision_sections(&t, &real, &mut |b| section(&mut payload, b));
            }
        }
    } else if with_values {
        let v: Vec<u8> = match &artifact.values {
            Values::F32(v) => le_bytes(v, f32::to_le_bytes),
            Values::F64(v) => le_bytes(v, f64::to_le_bytes),
        };
        section(&mut payload, &v);
    }
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len() + 8);
    out.extend_from_slice(&MAGIC);
    for field in [
        VERSION,
        value_bytes,
        parts.greedy_bytes,
        match parts.membership {
            Membership::Triangular => 0,
            Membership::Crisp => 1,
        },
        parts.cores.len() as u32,
        parts.sets.len() as u32,
    ] {
        out.extend_from_slice(&field.to_le_bytes());
    }
    out.extend_from_slice(&(artifact.greedy.len() as u64).to_le_bytes());
    out.extend_from_slice(&u32::from(with_values).to_le_bytes());
    // 2: decision tables with `V` in their order (1 was an earlier layout).
    out.extend_from_slice(&(2 * u32::from(options.decisions)).to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&[0; 8]);
    out.extend_from_slice(&payload);
    let crc = crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out.extend_from_slice(&[0; 4]);
    Ok(out)
}

/// Columns a generated line fills at most (rustfmt's default width).
const WIDTH: usize = 100;

/// `values` (already written as source) as the elements of a Rust array literal, indented by
/// `indent` spaces, as many to a line as fit in [`WIDTH`]. Floats are written with `{:?}`, the
/// shortest form that parses back to the same bits.
fn elements(out: &mut String, indent: usize, values: impl IntoIterator<Item = String>) {
    let mut line = String::new();
    for v in values {
        if !line.is_empty() && indent + line.len() + 1 + v.len() + 1 > WIDTH {
            let _ = writeln!(out, "{:indent$}{line}", "");
            line.clear();
        }
        if !line.is_empty() {
            line.push(' ');
        }
        line.push_str(&v);
        line.push(',');
    }
    if !line.is_empty() {
        let _ = writeln!(out, "{:indent$}{line}", "");
    }
}

/// `artifact` as the source of a Rust module (with `V` if `with_values`): `static` arrays of
/// the cores, the actions, the greedy actions (`u8`, `u16` or `u32`) and `V`, and a
/// `view()` that checks them into a [`fuzzyq_core::view::PolicyView`] without allocating.
/// The module needs only `fuzzyq-core` (no default features) and is meant for `mod name;`.
pub fn export_rust(artifact: &PolicyArtifact, with_values: bool) -> Result<String, SimError> {
    let parts = Parts::of(artifact)?;
    let t = if parts.value_bytes() == 4 {
        "f32"
    } else {
        "f64"
    };
    let g = match parts.greedy_bytes {
        1 => "u8",
        2 => "u16",
        _ => "u32",
    };
    let as_t = |x: f64| -> String {
        if t == "f32" {
            format!("{:?}", x as f32)
        } else {
            format!("{x:?}")
        }
    };
    let n_cores = artifact.greedy.len();
    let (n_dims, n_agents) = (parts.cores.len(), parts.sets.len());
    let mut s = String::new();
    let _ = writeln!(
        s,
        "//! A fuzzy Q-iteration policy, generated by `fuzzyq export --format rust` (regenerate it \
         rather\n//! than edit it): {n_cores} cores over {n_dims} state variables, {n_agents} \
         agent(s), {} joint actions,\n//! `{t}` values, greedy actions as `{g}`{}.\n//!\n//! \
         `view()` checks the arrays into a `fuzzyq_core::view::PolicyView` (no allocation); it \
         acts\n//! with `interpolated_action(x, u)`. The module needs only `fuzzyq-core` with \
         no default features;\n//! declare it with `#[rustfmt::skip]` to keep its long \
         arrays as they are.\n",
        parts.n_joint(),
        if with_values {
            ", with V"
        } else {
            ", without V"
        },
    );
    // Cores at multiples of pi are data, not approximations of the constant.
    s.push_str(
        "#![allow(clippy::approx_constant)]\n\n\
         use fuzzyq_core::view::{Greedy, PolicyView, ViewError};\n\
         use fuzzyq_core::{ActionSet, JointActions, Membership, ProductPartition};\n",
    );
    let _ = writeln!(
        s,
        "\n/// The cores of each state variable, increasing.\npub static CORES: [&[{t}]; \
         {n_dims}] = ["
    );
    for c in &parts.cores {
        s.push_str("    &[\n");
        elements(&mut s, 8, c.iter().map(|&x| as_t(x)));
        s.push_str("    ],\n");
    }
    s.push_str("];\n");
    let _ = writeln!(
        s,
        "\n/// Each agent's actions (the components of each action in turn) and the components \
         per\n/// action.\npub static ACTIONS: [(&[{t}], usize); {n_agents}] = ["
    );
    for (_, dim, values) in &parts.sets {
        s.push_str("    (\n        &[\n");
        elements(&mut s, 12, values.iter().map(|&x| as_t(x)));
        let _ = writeln!(s, "        ],\n        {dim},\n    ),");
    }
    s.push_str("];\n");
    let _ = writeln!(
        s,
        "\n/// The greedy joint action of each core (row-major core order).\npub static GREEDY: \
         [{g}; {n_cores}] = ["
    );
    elements(&mut s, 4, artifact.greedy.iter().map(|u| u.to_string()));
    s.push_str("];\n");
    if with_values {
        let _ = writeln!(
            s,
            "\n/// `V` at each core (row-major core order).\npub static V: [{t}; {n_cores}] = ["
        );
        match &artifact.values {
            Values::F32(v) => elements(&mut s, 4, v.iter().map(|x| format!("{x:?}"))),
            Values::F64(v) => elements(&mut s, 4, v.iter().map(|x| format!("{x:?}"))),
        }
        s.push_str("];\n");
    }
    let membership = match parts.membership {
        Membership::Triangular => "Triangular",
        Membership::Crisp => "Crisp",
    };
    let greedy_variant = g.to_uppercase();
    let v = if with_values { "Some(&V)" } else { "None" };
    let _ = write!(
        s,
        "
/// The policy's view of the arrays above, checked (no allocation).
pub fn view() -> Result<PolicyView<'static, {t}>, ViewError> {{
    let grid = ProductPartition::try_new(&CORES)
        .map_err(ViewError::Grid)?
        .with_membership(Membership::{membership});
    let mut sets = [ActionSet::default(); {n_agents}];
    for (set, &(values, dim)) in sets.iter_mut().zip(&ACTIONS) {{
        *set = ActionSet::try_new(values, dim).map_err(ViewError::Actions)?;
    }}
    let joint = JointActions::try_new(&sets).map_err(ViewError::Actions)?;
    PolicyView::from_parts(grid, joint, Greedy::{greedy_variant}(&GREEDY), {v})
}}
"
    );
    Ok(s)
}

/// An exported policy in memory for a controller with `std`: at a page boundary (so at the
/// 8-byte boundary [`fuzzyq_core::view::PolicyView::parse`] needs) and, on Linux, advised
/// into transparent huge pages. A greedy decision reads a box of `V` scattered over megabytes;
/// with huge pages those reads miss the TLB less (BENCHMARKS.md, "Exported policies on a
/// controller": 62 instead of 67 us on the paper's grid). Where the kernel does not give huge
/// pages the advice is ignored and the bytes are the same.
#[derive(Debug)]
pub struct ExportedBytes {
    map: memmap2::MmapMut,
    len: usize,
}

impl ExportedBytes {
    /// Reads the exported file at `path`.
    pub fn read(path: &Path) -> Result<Self, SimError> {
        let bytes = std::fs::read(path).map_err(|error| PolicyFileError::Read {
            path: path.to_path_buf(),
            error,
        })?;
        Self::copy_of(&bytes).map_err(|error| {
            PolicyFileError::Read {
                path: path.to_path_buf(),
                error,
            }
            .into()
        })
    }

    /// `bytes` copied into a fresh mapping.
    pub fn copy_of(bytes: &[u8]) -> std::io::Result<Self> {
        let mut map = memmap2::MmapMut::map_anon(bytes.len().max(1))?;
        #[cfg(target_os = "linux")]
        {
            // Advice only: a kernel without transparent huge pages refuses it, and the
            // mapping works the same.
            let _ = map.advise(memmap2::Advice::HugePage);
        }
        map[..bytes.len()].copy_from_slice(bytes);
        Ok(Self {
            map,
            len: bytes.len(),
        })
    }

    /// The exported bytes.
    #[must_use]
    pub fn bytes(&self) -> &[u8] {
        &self.map[..self.len]
    }
}
