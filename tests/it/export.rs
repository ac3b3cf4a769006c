//! Exported policies (`fuzzyq_sim::io::export`) read in place by the core's `PolicyView`: the
//! interpolated action and `V` at any state have the bits of the policy they were exported
//! from, the greedy actions take the smallest integer type, and damaged, cut, misaligned or
//! foreign bytes are refused with typed errors.

use std::ops::ControlFlow;

use fuzzyq_core::solver::{BackupPath, Operator};
use fuzzyq_core::view::{DecideError, Greedy, PolicyView, ViewError, ViewReal, crc32};
use fuzzyq_core::{EvalError, q, solver::Precision};
use fuzzyq_sim::io::config::{EnvConfig, GridConfig, TrainConfig};
use fuzzyq_sim::io::export::{ExportOptions, ExportedBytes, export_bytes};
use fuzzyq_sim::io::policy_file::{PolicyArtifact, Values};
use fuzzyq_sim::model::Wide;

use crate::alloc_count::allocations;

/// The point masses on a coarse grid (5 position x 3 velocity cores per axis).
fn trained(agents: usize, precision: Precision) -> PolicyArtifact {
    let (pos, vel) = (vec![-6.0, -3.0, 0.0, 3.0, 6.0], vec![-3.0, 0.0, 3.0]);
    trained_on(agents, precision, &pos, &vel, false)
}

/// The point masses on a grid of `pos` x `vel` cores per axis; with `patches`, on a floor
/// with a rough patch, so that each agent is one block of four variables (else two of two).
fn trained_on(
    agents: usize,
    precision: Precision,
    pos: &[f64],
    vel: &[f64],
    patches: bool,
) -> PolicyArtifact {
    let mut config = TrainConfig::default();
    if let EnvConfig::Pointmass(p) = &mut config.env {
        p.agents = agents;
        if patches {
            p.integrator = fuzzyq_sim::model::pointmass::Integrator::Rk4;
            p.friction = fuzzyq_tests::friction_patch();
        }
    }
    let mut cores = Vec::new();
    for _ in 0..agents {
        cores.extend([pos.to_vec(), pos.to_vec(), vel.to_vec(), vel.to_vec()]);
    }
    config.grid = GridConfig::explicit(cores);
    config.solver.precision = precision;
    fuzzyq_sim::train::train(&config, |_| ControlFlow::Continue(())).unwrap()
}

/// `bytes` copied to an 8-byte boundary (plus `shift` bytes) of a fresh buffer.
fn placed(bytes: &[u8], shift: usize) -> (Vec<u8>, usize) {
    let mut buf = vec![0u8; bytes.len() + 16];
    let at = buf.as_ptr().align_offset(8) + shift;
    buf[at..at + bytes.len()].copy_from_slice(bytes);
    (buf, at)
}

/// States spread over the grid's range, from a fixed sequence.
fn states(dim: usize, n: usize) -> Vec<Vec<f64>> {
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    (0..n)
        .map(|_| {
            (0..dim)
                .map(|d| {
                    s = s.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
                    let u = (s >> 11) as f64 / (1u64 << 53) as f64;
                    let range = if d % 4 < 2 { 7.0 } else { 3.5 };
                    (2.0 * u - 1.0) * range
                })
                .collect()
        })
        .collect()
}

/// The view of `artifact`'s export answers as the policy does, bit for bit; returns the
/// bytes per greedy action it stored.
fn same_decisions<T: ViewReal + Wide>(artifact: &PolicyArtifact, values: &[T]) -> usize {
    let bytes = export_bytes(artifact, ExportOptions::default()).unwrap();
    let (buf, at) = placed(&bytes, 0);
    let view = PolicyView::<T>::parse(&buf[at..at + bytes.len()]).unwrap();
    let model = artifact.config.build_model().unwrap();
    let grid = artifact.config.grid::<T>().unwrap();
    let joint = fuzzyq_core::model::joint_actions::<T, _>(&model).unwrap();
    assert_eq!(view.grid().n_cores(), grid.n_cores());
    let bits = |v: &[T]| v.iter().map(|x| x.to_f64().to_bits()).collect::<Vec<_>>();
    for x in states(grid.n_dims(), 300) {
        let x: Vec<T> = x.iter().map(|&v| T::from_f64(v)).collect();
        let (mut a, mut b) = (vec![T::ZERO; joint.dim()], vec![T::ZERO; joint.dim()]);
        view.interpolated_action(&x, &mut a).unwrap();
        q::interpolated_action(&grid.view(), &joint, &artifact.greedy, &x, &mut b).unwrap();
        assert_eq!(
            bits(&a),
            bits(&b),
            "at {:?}",
            x.iter().map(|v| v.to_f64()).collect::<Vec<_>>()
        );
        let v = view.value(&x).unwrap().unwrap();
        let w = grid.view().active(&x).unwrap().interpolate(values);
        assert_eq!(v.to_f64().to_bits(), w.to_f64().to_bits());
    }
    match view.greedy() {
        Greedy::U8(_) => 1,
        Greedy::U16(_) => 2,
        Greedy::U32(_) => 4,
    }
}

#[test]
fn exported_policies_decide_as_the_policy_in_the_smallest_action_type() {
    // One agent: 25 joint actions in a byte; two: 625 in two bytes; both precisions.
    let one = trained(1, Precision::F32);
    let Values::F32(v) = &one.values else {
        unreachable!()
    };
    assert_eq!(same_decisions(&one, v), 1);
    let two = trained(2, Precision::F32);
    let Values::F32(v) = &two.values else {
        unreachable!()
    };
    assert_eq!(same_decisions(&two, v), 2);
    let one64 = trained(1, Precision::F64);
    let Values::F64(v) = &one64.values else {
        unreachable!()
    };
    same_decisions(&one64, v);
    // Without V: the interpolated policy still acts; `value` says there is none.
    let bytes = export_bytes(
        &one,
        ExportOptions {
            values: false,
            decisions: false,
        },
    )
    .unwrap();
    let (buf, at) = placed(&bytes, 0);
    let view = PolicyView::<f32>::parse(&buf[at..at + bytes.len()]).unwrap();
    assert!(view.values().is_none() && view.value(&[0.0; 4]).is_none());
    let mut u = [0.0f32; 2];
    view.interpolated_action(&[-4.0, 3.0, 0.0, 0.0], &mut u)
        .unwrap();
}

#[test]
fn reading_and_acting_with_a_view_allocate_nothing() {
    for agents in [1, 2] {
        let artifact = trained(agents, Precision::F32);
        let bytes = export_bytes(&artifact, ExportOptions::default()).unwrap();
        let (buf, at) = placed(&bytes, 0);
        let xs: Vec<Vec<f32>> = states(4 * agents, 200)
            .iter()
            .map(|x| x.iter().map(|&v| v as f32).collect())
            .collect();
        let mut u = vec![0.0f32; 2 * agents];
        let (sum, n) = allocations(|| {
            let view = PolicyView::<f32>::parse(&buf[at..at + bytes.len()]).unwrap();
            let mut sum = 0.0;
            for x in &xs {
                view.interpolated_action(x, &mut u).unwrap();
                sum += u[0] + view.value(x).unwrap().unwrap();
            }
            // And a view of parts in memory, as a generated module builds it.
            let again =
                PolicyView::from_parts(*view.grid(), *view.joint(), view.greedy(), view.values())
                    .unwrap();
            again.interpolated_action(&xs[0], &mut u).unwrap();
            sum + u[0]
        });
        assert!(sum.is_finite());
        assert_eq!(n, 0, "{agents} agent(s): {n} allocations");
    }
}

/// The view's greedy decisions from its decision tables equal the solver's `Q(x, .)` bit for
/// bit (and allocate nothing).
fn same_greedy<T: ViewReal + Wide>(artifact: &PolicyArtifact, values: &[T])
where
    fuzzyq_sim::model::EnvModel: fuzzyq_core::Model<T> + Sync,
{
    let options = ExportOptions {
        values: true,
        decisions: true,
    };
    let bytes = export_bytes(artifact, options).unwrap();
    let (buf, at) = placed(&bytes, 0);
    let view = PolicyView::<T>::parse(&buf[at..at + bytes.len()]).unwrap();
    assert!(view.has_decision_tables());
    let model = artifact.config.build_model().unwrap();
    let grid = artifact.config.grid::<T>().unwrap();
    let backup = fuzzyq_core::Backup::discounted(T::from_f64(artifact.config.solver.gamma));
    let op = Operator::new(&model, grid.view(), backup, BackupPath::Auto).unwrap();
    let m = view.joint().n_joint();
    let mut scratch = vec![0u64; view.decision_scratch_len().unwrap()];
    let (mut a, mut b) = (vec![T::ZERO; m], vec![T::ZERO; m]);
    let mut u = vec![T::ZERO; view.joint().dim()];
    let bits = |v: &[T]| v.iter().map(|x| x.to_f64().to_bits()).collect::<Vec<_>>();
    for x in states(grid.n_dims(), 300) {
        let x: Vec<T> = x.iter().map(|&v| T::from_f64(v)).collect();
        let (best, n) = allocations(|| view.greedy_action(&x, &mut scratch, &mut a, &mut u));
        assert_eq!(n, 0, "allocations in a greedy decision");
        op.q_values(values, &x, &mut b).unwrap();
        assert_eq!(bits(&a), bits(&b));
        assert_eq!(best.unwrap(), q::argmax(&b).unwrap());
        // `V` is stored in the tables' decision order; its interpolation keeps the bits.
        let value = grid.view().active(&x).unwrap().interpolate(values);
        assert_eq!(
            view.value(&x).unwrap().unwrap().to_f64().to_bits(),
            value.to_f64().to_bits()
        );
    }
    let (strides, stored) = (view.value_strides(), view.values().unwrap());
    let mut idx = vec![0usize; grid.n_dims()];
    for (i, &v) in values.iter().enumerate().step_by(97) {
        grid.view().unravel(i, &mut idx).unwrap();
        let at: usize = idx.iter().zip(strides).map(|(i, s)| i * s).sum();
        assert_eq!(stored[at].to_f64().to_bits(), v.to_f64().to_bits());
    }
    // The model's backup reads `V` in grid order, so it is refused on this export.
    let mut s = vec![T::ZERO; fuzzyq_core::backup::scratch_len(grid.n_dims(), u.len())];
    let mut row = vec![T::ZERO; m];
    assert_eq!(
        view.q_values_with_model(
            &model,
            backup,
            &vec![T::ZERO; grid.n_dims()],
            &mut s,
            &mut row,
            &mut a
        ),
        Err(DecideError::DecisionOrder)
    );
    // Too little scratch, and a state of the wrong length, are refused.
    let short = scratch.len() - 1;
    assert!(matches!(
        view.q_values(&vec![T::ZERO; grid.n_dims()], &mut scratch[..short], &mut a),
        Err(DecideError::Eval(EvalError::Length { .. }))
    ));
    assert!(view.q_values(&[T::ZERO], &mut scratch, &mut a).is_err());
}

#[test]
fn greedy_decisions_from_the_decision_tables_have_the_solvers_bits() {
    let one = trained(1, Precision::F32);
    let Values::F32(v) = &one.values else {
        unreachable!()
    };
    same_greedy(&one, v);
    let two = trained(2, Precision::F32);
    let Values::F32(v) = &two.values else {
        unreachable!()
    };
    same_greedy(&two, v);
    let two64 = trained(2, Precision::F64);
    let Values::F64(v) = &two64.values else {
        unreachable!()
    };
    same_greedy(&two64, v);
    // 1 to 6 blocks: one agent on a rough floor (one block of four variables), one and two
    // agents of each kind, three agents of three blocks and of six (coarser grids).
    let (pos, vel) = ([-6.0, -3.0, 0.0, 3.0, 6.0], [-3.0, 0.0, 3.0]);
    let (pos3, vel3) = ([-6.0, 0.0, 6.0], [-3.0, 3.0]);
    for (agents, patches, pos, vel) in [
        (1, true, &pos[..], &vel[..]),
        (2, true, &pos3[..], &vel3[..]),
        (3, true, &pos3[..], &vel3[..]),
        (3, false, &pos3[..], &vel3[..]),
    ] {
        let artifact = trained_on(agents, Precision::F32, pos, vel, patches);
        let Values::F32(v) = &artifact.values else {
            unreachable!()
        };
        same_greedy(&artifact, v);
    }
    // Without tables, the view says so; tables without V are refused at export.
    let bytes = export_bytes(&one, ExportOptions::default()).unwrap();
    let (buf, at) = placed(&bytes, 0);
    let view = PolicyView::<f32>::parse(&buf[at..at + bytes.len()]).unwrap();
    assert_eq!(view.decision_scratch_len(), None);
    let mut q = [0.0f32; 25];
    assert_eq!(
        view.q_values(&[0.0; 4], &mut [0; 4], &mut q),
        Err(DecideError::NoTables)
    );
    let options = ExportOptions {
        values: false,
        decisions: true,
    };
    assert!(export_bytes(&one, options).is_err());
}

#[test]
fn decision_tables_with_an_empty_row_are_refused() {
    // One point mass in f32: the first block's row starts follow the header, the sections of
    // the grid, actions, greedy actions and V, and the tables' shapes, variables and joint
    // actions (every section padded to 8 bytes).
    let artifact = trained(1, Precision::F32);
    let options = ExportOptions {
        values: true,
        decisions: true,
    };
    let mut bytes = export_bytes(&artifact, options).unwrap();
    let (buf, at) = placed(&bytes, 0);
    let view = PolicyView::<f32>::parse(&buf[at..at + bytes.len()]).unwrap();
    let pad = |n: usize| n.div_ceil(8) * 8;
    let (e, n) = (view.grid().n_dims(), view.grid().n_cores());
    let cores: usize = (0..e).map(|d| view.grid().dim(d).n_cores()).sum();
    let (m, dim) = (view.joint().n_joint(), view.joint().dim());
    let mut ptr =
        64 + pad(4 * e) + pad(8) + pad(4 * cores) + pad(4 * m * dim) + pad(n) + pad(4 * n);
    let nb = u32::from_le_bytes(bytes[ptr..ptr + 4].try_into().unwrap()) as usize;
    ptr += 8 + pad(16 * nb) + pad(4 * e) + pad(4 * m);
    let first = |b: &[u8], i: usize| {
        u32::from_le_bytes(b[ptr + 4 * i..ptr + 4 * i + 4].try_into().unwrap())
    };
    assert_eq!(first(&bytes, 0), 0, "the first row start");
    assert!(first(&bytes, 1) > 0);
    // Row 0 emptied (its entries handed to row 1), the checksum made right again.
    bytes[ptr + 4..ptr + 8].copy_from_slice(&0u32.to_le_bytes());
    let end = bytes.len() - 8;
    let crc = crc32(&bytes[..end]);
    bytes[end..end + 4].copy_from_slice(&crc.to_le_bytes());
    let (buf, at) = placed(&bytes, 0);
    assert_eq!(
        PolicyView::<f32>::parse(&buf[at..at + bytes.len()]).unwrap_err(),
        ViewError::Header {
            what: "decision block rows"
        }
    );
    // Tables flagged 1 (an earlier layout, with `V` in grid order) are refused by name.
    let mut bytes = export_bytes(&artifact, options).unwrap();
    assert_eq!(bytes[44..48], 2u32.to_le_bytes());
    bytes[44..48].copy_from_slice(&1u32.to_le_bytes());
    let crc = crc32(&bytes[..end]);
    bytes[end..end + 4].copy_from_slice(&crc.to_le_bytes());
    let (buf, at) = placed(&bytes, 0);
    let err = PolicyView::<f32>::parse(&buf[at..at + bytes.len()]).unwrap_err();
    assert!(err.to_string().contains("export the policy again"), "{err}");
}

#[test]
fn exported_bytes_read_back_for_a_std_controller() {
    let artifact = trained(1, Precision::F32);
    let bytes = export_bytes(&artifact, ExportOptions::default()).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.bin");
    std::fs::write(&path, &bytes).unwrap();
    let loaded = ExportedBytes::read(&path).unwrap();
    assert_eq!(loaded.bytes(), &bytes[..]);
    PolicyView::<f32>::parse(loaded.bytes()).unwrap();
    let missing = ExportedBytes::read(&dir.path().join("none.bin")).unwrap_err();
    assert!(missing.to_string().contains("none.bin"), "{missing}");
}

#[test]
fn a_view_of_parts_checks_them() {
    let artifact = trained(1, Precision::F32);
    let bytes = export_bytes(&artifact, ExportOptions::default()).unwrap();
    let (buf, at) = placed(&bytes, 0);
    let view = PolicyView::<f32>::parse(&buf[at..at + bytes.len()]).unwrap();
    let (grid, joint) = (*view.grid(), *view.joint());
    let n = grid.n_cores();
    let short = vec![0u8; n - 1];
    assert!(matches!(
        PolicyView::from_parts(grid, joint, Greedy::U8(&short), None),
        Err(ViewError::Actions(EvalError::Length { .. }))
    ));
    let mut bad = vec![0u8; n];
    bad[n / 2] = 25;
    assert!(matches!(
        PolicyView::from_parts(grid, joint, Greedy::U8(&bad), None),
        Err(ViewError::Actions(EvalError::OutOfRange { index: 25, .. }))
    ));
    let v = vec![0.0f32; n + 1];
    assert!(matches!(
        PolicyView::from_parts(grid, joint, view.greedy(), Some(&v)),
        Err(ViewError::Actions(EvalError::Length { what: "V", .. }))
    ));
}

#[test]
fn damaged_cut_misaligned_or_foreign_bytes_are_refused() {
    let artifact = trained(1, Precision::F32);
    let bytes = export_bytes(&artifact, ExportOptions::default()).unwrap();
    let parse = |b: &[u8], shift: usize| -> Result<(), ViewError> {
        let (buf, at) = placed(b, shift);
        PolicyView::<f32>::parse(&buf[at..at + b.len()]).map(|_| ())
    };
    assert_eq!(parse(&bytes, 0), Ok(()));
    // A flipped bit anywhere in the header (but the payload length, which locates the
    // checksum) or the payload: reported as damage, before any field is believed.
    for at in [9, 13, 17, 30, 40, 70, bytes.len() / 2, bytes.len() - 12] {
        for bit in [0x01, 0x10] {
            let mut b = bytes.clone();
            b[at] ^= bit;
            let r = parse(&b, 0);
            assert!(
                matches!(r, Err(ViewError::Checksum { .. })),
                "byte {at}: {r:?}"
            );
        }
    }
    // Cut short, at any length.
    for len in [0, 4, 8, 40, 64, 100, bytes.len() - 8, bytes.len() - 1] {
        let r = parse(&bytes[..len], 0);
        assert!(
            matches!(r, Err(ViewError::Truncated { .. })),
            "{len} bytes: {r:?}"
        );
    }
    // Not at an 8-byte boundary; another file; another precision; another version.
    assert_eq!(parse(&bytes, 4), Err(ViewError::Misaligned));
    assert_eq!(
        parse(b"\x89FZQCKP\n and more bytes", 0),
        Err(ViewError::NotAPolicy)
    );
    let (buf, at) = placed(&bytes, 0);
    assert_eq!(
        PolicyView::<f64>::parse(&buf[at..at + bytes.len()]).map(|_| ()),
        Err(ViewError::Precision {
            found: 4,
            expected: 8
        })
    );
    let mut b = bytes.clone();
    b[8] = 2;
    let end = b.len() - 8;
    let crc = crc32(&b[..end]);
    b[end..end + 4].copy_from_slice(&crc.to_le_bytes());
    assert_eq!(parse(&b, 0), Err(ViewError::Version { found: 2 }));
    // Every error says what is wrong in one line.
    for e in [
        ViewError::Misaligned,
        ViewError::NotAPolicy,
        ViewError::Version { found: 2 },
    ] {
        let m = e.to_string();
        assert!(!m.contains('\n'), "{m}");
        assert!(
            m.starts_with("exported policy") || m.starts_with("not an exported"),
            "{m}"
        );
    }
}
