//! Exported policies: a fuzzy Q-iteration policy in the compact format that
//! [`fuzzyq_core::view::PolicyView`] reads in place on a `no_std` controller (the format is
//! specified there): the grid, each agent's actions, the per-core greedy actions in the
//! smallest integer type that holds them, and optionally `V`, in the policy's precision.

use fuzzyq_core::Model;
use fuzzyq_core::view::{HEADER_LEN, MAGIC, VERSION, crc32, padding};

use crate::error::SimError;
use crate::io::policy_file::{PolicyArtifact, Values};

/// The bytes of `artifact` exported (with `V` if `with_values`).
pub fn export_bytes(artifact: &PolicyArtifact, with_values: bool) -> Result<Vec<u8>, SimError> {
    let config = &artifact.config;
    let model = config.build_model()?;
    let cores = config.grid_cores();
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
    let (value_bytes, v): (u32, Vec<u8>) = match &artifact.values {
        Values::F32(v) => (4, v.iter().flat_map(|x| x.to_le_bytes()).collect()),
        Values::F64(v) => (8, v.iter().flat_map(|x| x.to_le_bytes()).collect()),
    };
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
    let counts: Vec<u8> = cores
        .iter()
        .flat_map(|c| (c.len() as u32).to_le_bytes())
        .collect();
    section(&mut payload, &counts);
    let shapes: Vec<u8> = sets
        .iter()
        .flat_map(|s| [(s.0 as u32).to_le_bytes(), (s.1 as u32).to_le_bytes()])
        .flatten()
        .collect();
    section(&mut payload, &shapes);
    let core_values: Vec<u8> = cores.iter().flatten().flat_map(|&x| real(x)).collect();
    section(&mut payload, &core_values);
    let action_values: Vec<u8> = sets
        .iter()
        .flat_map(|s| &s.2)
        .flat_map(|&x| real(x))
        .collect();
    section(&mut payload, &action_values);
    let greedy: Vec<u8> = match greedy_bytes {
        1 => artifact.greedy.iter().map(|&u| u as u8).collect(),
        2 => artifact
            .greedy
            .iter()
            .flat_map(|&u| (u as u16).to_le_bytes())
            .collect(),
        _ => artifact
            .greedy
            .iter()
            .flat_map(|&u| u.to_le_bytes())
            .collect(),
    };
    section(&mut payload, &greedy);
    if with_values {
        section(&mut payload, &v);
    }
    let mut out = Vec::with_capacity(HEADER_LEN + payload.len() + 8);
    out.extend_from_slice(&MAGIC);
    for field in [
        VERSION,
        value_bytes,
        greedy_bytes,
        match config.grid.membership {
            fuzzyq_core::Membership::Triangular => 0,
            fuzzyq_core::Membership::Crisp => 1,
        },
        cores.len() as u32,
        n_agents as u32,
    ] {
        out.extend_from_slice(&field.to_le_bytes());
    }
    out.extend_from_slice(&(artifact.greedy.len() as u64).to_le_bytes());
    out.extend_from_slice(&u32::from(with_values).to_le_bytes());
    out.extend_from_slice(&[0; 4]);
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&[0; 8]);
    out.extend_from_slice(&payload);
    let crc = crc32(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out.extend_from_slice(&[0; 4]);
    Ok(out)
}
