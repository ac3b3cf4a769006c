//! Tests of the parent module.

use super::*;
use crate::backup::{SparseRows, contract};
use proptest::prelude::*;

/// Random rows: `n_rows` rows of 0 to 5 entries (non-negative weights, some zero rows).
fn rows_strategy(n_rows: usize, n_cols: usize) -> impl Strategy<Value = RowsBuf<f32>> {
    prop::collection::vec(
        prop::collection::vec((0..n_cols as u32, 0.0f32..1.0), 0..6),
        n_rows,
    )
    .prop_map(move |rows| {
        let mut ptr = vec![0u32];
        let (mut col, mut weight) = (Vec::new(), Vec::new());
        for r in rows {
            for (k, w) in r {
                col.push(k);
                weight.push(w);
            }
            ptr.push(col.len() as u32);
        }
        RowsBuf::new(ptr, col, weight, n_cols).expect("valid rows")
    })
}

/// `input` followed by [`INPUT_PAD`] NaNs: what an over-reading instance may load and must
/// discard.
fn padded(input: &[f32]) -> Vec<f32> {
    let mut v = input.to_vec();
    v.extend([f32::NAN; INPUT_PAD]);
    v
}

fn values(n: usize, seed: u64) -> Vec<f32> {
    let mut s = seed | 1;
    (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            ((s >> 40) as f32 / (1u64 << 24) as f32) * 200.0 - 100.0
        })
        .collect()
}

/// A shape: block cores, actions, successor cores, r_len, p_len (covering masked tails,
/// single lanes, rows longer than a register block, and many rows of a few values, which
/// the instances with range stores pack several to a vector).
fn shape() -> impl Strategy<Value = (usize, usize, usize, usize, usize)> {
    let rp = prop_oneof![
        (1usize..5, prop_oneof![1usize..40, 120usize..300]),
        (8usize..50, 1usize..9),
    ];
    (1usize..4, 1usize..7, 1usize..9, rp).prop_map(|(c, a, k, (r, p))| (c, a, k, r, p))
}

/// A [`shape`] with random rows for its block cores' actions over its successor cores.
fn shaped_rows() -> impl Strategy<Value = ((usize, usize, usize, usize, usize), RowsBuf<f32>)> {
    shape().prop_flat_map(|sh| (Just(sh), rows_strategy(sh.0 * sh.1, sh.2)))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// A stage at any strides (the view reads `V` in place this way) equals, on every
    /// instance, the chain `fma(w_e, in[k_e K + r S + p], acc)` from 0 in row order.
    #[test]
    fn strided_stages_sum_each_row_in_order_on_every_instance(
        ((n_c, na, n_k, r_len, p_len), rows) in shaped_rows(),
        (k_extra, r_gap) in (0usize..50, prop_oneof![Just(0usize), 0usize..20]),
        (a_gap, action_outer) in (0usize..9, any::<bool>()),
        seed in any::<u64>(),
    ) {
        let r_stride = p_len + r_gap;
        let k_stride = r_len * r_stride + k_extra;
        let strides = Strides { k_stride, r_stride };
        let extent = (n_k - 1) * k_stride + (r_len - 1) * r_stride + p_len;
        let input = values(extent, seed);
        // Output at any strides too: actions inside or outside the leading index, with gaps.
        let os = if action_outer {
            OutStrides { r_stride: p_len + a_gap, a_stride: r_len * (p_len + a_gap) + a_gap }
        } else {
            OutStrides { r_stride: na * (p_len + a_gap) + a_gap, a_stride: p_len + a_gap }
        };
        let out_len = (r_len - 1) * os.r_stride + (na - 1) * os.a_stride + p_len;
        for k in f32::available() {
            for c in 0..n_c {
                let mut a = vec![0.0f32; out_len];
                (k.stage_at)(rows.view(), c * na, na, r_len, p_len, strides, os, &input, &mut a);
                for r in 0..r_len {
                    for u in 0..na {
                        let (cols, ws) = rows.view().row(c * na + u);
                        for p in 0..p_len {
                            let mut acc = 0.0f32;
                            for (&kc, &w) in cols.iter().zip(ws) {
                                acc = w.mul_add(input[kc as usize * k_stride + r * r_stride + p], acc);
                            }
                            let got = a[r * os.r_stride + u * os.a_stride + p];
                            prop_assert_eq!(got.to_bits(), acc.to_bits(), "{} kernels", k.name);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn every_instance_matches_the_scalar_one_bit_for_bit(
        ((n_c, na, n_k, r_len, p_len), rows) in shaped_rows(),
        seed in any::<u64>(),
    ) {
        // The rows also merged in groups of one core's actions, as the block path's tables
        // are: the instances with a vector wide enough bound a core's rows from the groups,
        // the scalar one row by row.
        let rows = rows.with_groups(na);
        // Every other case on few distinct values, so that expected values tie often.
        let input: Vec<f32> = values(n_k * r_len * p_len, seed)
            .into_iter()
            .map(|x| if seed % 2 == 0 { (x / 40.0).round() } else { x })
            .collect();
        let scalar = select::<f32>(Some(super::super::Kernel::Scalar)).unwrap();
        for k in f32::available() {
            for c in 0..n_c {
                let mut a = vec![0.0f32; r_len * na * p_len];
                let mut b = vec![0.0f32; r_len * na * p_len];
                k.stage(rows.view(), c * na, na, r_len, p_len, &input, &mut a);
                scalar.stage(rows.view(), c * na, na, r_len, p_len, &input, &mut b);
                prop_assert_eq!(&a, &b, "stage, {} kernels", k.name);
                // Padded input (NaN past the tensor): over-reading instances discard it.
                k.stage(rows.view(), c * na, na, r_len, p_len, &padded(&input), &mut a);
                prop_assert_eq!(&a, &b, "stage on padded input, {} kernels", k.name);

                // The unfused reference agrees to rounding.
                let sr = SparseRows { ptr: &rows.ptr, col: &rows.col, weight: &rows.weight };
                let mut r = vec![0.0f32; r_len * na * p_len];
                contract(sr, c * na, na, n_k, r_len, p_len, &input, &mut r).unwrap();
                for (x, y) in a.iter().zip(&r) {
                    prop_assert!((x - y).abs() <= 1e-4 * (1.0 + y.abs()));
                }
            }
            // The last stage over rows of length p_len (r_len = 1).
            let last_in = &input[..n_k * p_len];
            let dense = InRows::dense(p_len);
            // The same rows padded to whole cache lines plus a few (NaN in the padding, which
            // must never be read), as the block path lays out the stage before the last.
            // Rows shorter than a line are padded to a power of two instead.
            let stride = if seed % 3 == 0 && p_len <= 16 {
                p_len.next_power_of_two()
            } else {
                p_len.next_multiple_of(16) + seed as usize % 3
            };
            let padded_rows = InRows { p_len, stride };
            let mut spread = vec![f32::NAN; padded_rows.extent(n_k) + INPUT_PAD];
            for (kc, row) in last_in.chunks_exact(p_len).enumerate() {
                spread[kc * padded_rows.stride..][..p_len].copy_from_slice(row);
            }
            let mut bounds = vec![0.0f32; n_k];
            for abs in [false, true] {
                let mut m = vec![0.0f32; n_c];
                let mut ms = vec![0.0f32; n_c];
                (k.last)(rows.view(), 0, na, dense, abs, last_in, &mut m, &mut bounds, None);
                (scalar.last)(rows.view(), 0, na, dense, abs, last_in, &mut ms, &mut bounds, None);
                prop_assert_eq!(&m, &ms, "last, {} kernels", k.name);
                let mut mp = vec![0.0f32; n_c];
                let mut ap = vec![0u32; n_c];
                let args_p = (!abs).then_some(&mut ap[..]);
                (k.last)(rows.view(), 0, na, dense, abs, &padded(last_in), &mut mp, &mut bounds, args_p);
                prop_assert_eq!(&mp, &ms, "last on padded input, {} kernels", k.name);
                let mut mr = vec![0.0f32; n_c];
                let mut ar = vec![0u32; n_c];
                let args_r = (!abs).then_some(&mut ar[..]);
                (k.last)(rows.view(), 0, na, padded_rows, abs, &spread, &mut mr, &mut bounds, args_r);
                prop_assert_eq!(&mr, &ms, "last on padded rows, {} kernels", k.name);
                let mut args = vec![0u32; n_c];
                if !abs {
                    let mut ma = vec![0.0f32; n_c];
                    (k.last)(rows.view(), 0, na, dense, false, last_in, &mut ma, &mut bounds, Some(&mut args));
                    prop_assert_eq!(&ma, &m, "last with actions, {} kernels", k.name);
                    prop_assert_eq!(&ap, &args, "actions on padded input, {} kernels", k.name);
                    prop_assert_eq!(&ar, &args, "actions on padded rows, {} kernels", k.name);
                    // Evaluating the greedy actions gives the maxima, bit for bit.
                    let mut ev = vec![0.0f32; n_c];
                    (k.eval)(rows.view(), 0, na, dense.into(), last_in, &args, &mut ev);
                    prop_assert_eq!(&ev, &m, "evaluation of the greedy actions, {} kernels", k.name);
                    (k.eval)(rows.view(), 0, na, padded_rows.into(), &spread, &args, &mut ev);
                    prop_assert_eq!(&ev, &m, "evaluation on padded rows, {} kernels", k.name);
                    // The same rows transposed (`[p][k]`, the two-block evaluation's layout).
                    let mut tr = vec![f32::NAN; p_len * n_k];
                    for (kc, row) in last_in.chunks_exact(p_len).enumerate().take(n_k) {
                        for (p, &x) in row.iter().enumerate() {
                            tr[p * n_k + kc] = x;
                        }
                    }
                    let shape = EvalIn::transposed(p_len, n_k);
                    (k.eval)(rows.view(), 0, na, shape, &tr, &args, &mut ev);
                    prop_assert_eq!(&ev, &m, "evaluation on transposed rows, {} kernels", k.name);
                }
                // Pruned maxima equal the maxima of the full stage output.
                for c in 0..n_c {
                    let mut full = vec![0.0f32; na * p_len];
                    k.stage(rows.view(), c * na, na, 1, p_len, last_in, &mut full);
                    let want = full
                        .iter()
                        .map(|&x| if abs { x.abs() } else { x })
                        .fold(f32::NEG_INFINITY, f32::max);
                    prop_assert_eq!(m[c], want, "pruned maximum, core {}", c);
                    if !abs {
                        let first = full.iter().position(|&x| x == want).unwrap();
                        prop_assert_eq!(args[c] as usize, first, "argmax, core {}", c);
                    }
                }
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Merged in groups, each row's entries appear in its own order with its own weights
    /// (weight 0 elsewhere), so the chain over a group's steps in a row's lane is that row's
    /// own chain, bit for bit.
    #[test]
    fn merged_groups_keep_every_row_chain(
        ((n_c, na, n_k, _, _), rows) in shaped_rows(),
        seed in any::<u64>(),
    ) {
        prop_assume!(na >= 2);
        let x = values(n_k, seed);
        // As merged, and laid out for vectors of 1, 8 and 16 lanes (the same weights).
        let merged = rows.with_groups(na);
        for vector_lanes in [0, 1, 8, 16] {
            let mut rows = merged.clone();
            if vector_lanes > 0 {
                rows.set_group_lanes(vector_lanes);
            }
            let view = rows.view();
            prop_assert!(view.group(0, na + 1).is_none());
            for c in 0..n_c {
                let (cols, ws) = view.group(c, na).expect("merged in groups of na");
                let steps: Vec<&[f32]> = (0..cols.len()).map(|s| ws.step(s)).collect();
                // Every step starts on its own size's boundary, up to a cache line: a
                // whole-step load reads one line.
                let step_bytes = (ws.lanes * size_of::<f32>()).min(64);
                prop_assert!((0..cols.len()).all(|s| (ws.at(s) as usize).is_multiple_of(step_bytes)));
                // Zeros in a step's lanes past the group's actions.
                prop_assert!(steps.iter().all(|w| w[na..].iter().all(|&v| v == 0.0)));
                for a in 0..na {
                    let (rc, rw) = view.row(c * na + a);
                    let mut want = 0.0f32;
                    for (&k, &w) in rc.iter().zip(rw) {
                        want = w.mul_add(x[k as usize], want);
                    }
                    let mut got = 0.0f32;
                    for (&k, w) in cols.iter().zip(&steps) {
                        got = w[a].mul_add(x[k as usize], got);
                    }
                    prop_assert_eq!(got.to_bits(), want.to_bits(), "core {}, action {}", c, a);
                    // Every entry of the row is one step, in the row's order.
                    let taken: Vec<(u32, u32)> = cols
                        .iter()
                        .zip(&steps)
                        .filter(|(_, w)| w[a] != 0.0)
                        .map(|(&k, w)| (k, w[a].to_bits()))
                        .collect();
                    let own: Vec<(u32, u32)> = rc
                        .iter()
                        .zip(rw)
                        .filter(|(_, w)| **w != 0.0)
                        .map(|(&k, w)| (k, w.to_bits()))
                        .collect();
                    prop_assert_eq!(taken, own);
                }
            }
        }
    }
}

/// The last two stages for given actions (`eval_pair`) equal the stage kernel followed by the
/// last stage with actions, bit for bit, for the greedy actions of every core, on the stage
/// kernel's layout and on every action-major layout of the same input.
#[test]
fn evaluating_two_stages_matches_the_full_stages() {
    // Block rows: 3 block cores x 2 actions over 4 successor block cores.
    let block = RowsBuf::new(
        vec![0, 2, 3, 6, 8, 9, 11],
        vec![0, 3, 1, 0, 2, 3, 1, 2, 3, 0, 1],
        vec![0.25, 0.75, 1.0, 0.2, 0.3, 0.5, 0.6, 0.4, 1.0, 0.9, 0.1],
        4,
    )
    .unwrap();
    for (r_len, p_len) in [(5usize, 1usize), (5, 3), (7, 13), (4, 6)] {
        // Last rows: r_len cores x 3 actions over r_len successor cores.
        let (mut ptr, mut col, mut weight) = (vec![0u32], Vec::new(), Vec::new());
        for i in 0..r_len * 3 {
            col.extend([(i % r_len) as u32, ((i * 2 + 1) % r_len) as u32]);
            weight.extend([0.625f32, 0.375]);
            ptr.push(col.len() as u32);
        }
        let last = RowsBuf::new(ptr, col, weight, r_len).unwrap();
        let input: Vec<f32> = values(4 * r_len * p_len, 11)
            .into_iter()
            .map(|x| (x / 30.0).round())
            .collect();
        for k in f32::available() {
            for c in 0..3 {
                let mut staged = vec![0.0f32; r_len * 2 * p_len];
                k.stage(block.view(), c * 2, 2, r_len, p_len, &input, &mut staged);
                let mut bounds = vec![0.0f32; r_len];
                let (mut m, mut args) = (vec![0.0f32; r_len], vec![0u32; r_len]);
                (k.last)(
                    last.view(),
                    0,
                    3,
                    InRows::dense(2 * p_len),
                    false,
                    &staged,
                    &mut m,
                    &mut bounds,
                    Some(&mut args),
                );
                for p_in in (1..=p_len).filter(|d| p_len % d == 0) {
                    // `input[(j R + k) P + q P_in + p_in]` moved to
                    // `[((q J + j) R + k) P_in + p_in]`.
                    let mut moved = vec![f32::NAN; input.len()];
                    for (i, &x) in input.iter().enumerate() {
                        let (jk, p) = (i / p_len, i % p_len);
                        let (q, pi) = (p / p_in, p % p_in);
                        moved[(q * 4 * r_len + jk) * p_in + pi] = x;
                    }
                    // With the shared path's scratch (used when `p_in` is 1) and without.
                    let (inner, slots) = PairScratch::<f32>::lens(r_len, 2, p_len, r_len);
                    for lens in [(inner, slots), (0, 0)] {
                        let mut ev = vec![0.0f32; r_len];
                        let (mut inner, mut slots) = (vec![f32::NAN; lens.0], vec![7u32; lens.1]);
                        (k.eval_pair)(
                            block.view(),
                            c,
                            last.view(),
                            (2, 3),
                            (p_len, p_in),
                            &moved,
                            &args,
                            &mut ev,
                            PairScratch {
                                inner: &mut inner,
                                slots: &mut slots,
                            },
                        );
                        assert_eq!(
                            ev, m,
                            "{} kernels, r {r_len}, p {p_len} ({p_in} inner), core {c}, scratch {lens:?}",
                            k.name
                        );
                    }
                }
            }
        }
    }
}

#[test]
fn rows_are_validated() {
    assert!(RowsBuf::new(vec![0, 1], vec![3], vec![0.5f32], 3).is_none());
    assert!(RowsBuf::new(vec![0, 1], vec![2], vec![-0.5f32], 3).is_none());
    assert!(RowsBuf::new(vec![0, 2], vec![2], vec![0.5f32], 3).is_none());
    assert!(RowsBuf::new(vec![0, 1], vec![2], vec![0.5f32], 3).is_some());
}

#[test]
fn f64_instances_match_too() {
    let rows = RowsBuf::new(
        vec![0, 2, 3, 7],
        vec![0, 2, 1, 0, 1, 2, 2],
        vec![0.25, 0.75, 1.0, 0.1, 0.2, 0.3, 0.4],
        3,
    )
    .unwrap();
    // (Rows of 3 and 4 values over 20 and 37 leading indices: packed on range stores.)
    for (r_len, p_len) in [(2, 1), (2, 5), (2, 13), (2, 130), (20, 3), (37, 4)] {
        let input: Vec<f64> = values(3 * r_len * p_len, 9)
            .into_iter()
            .map(f64::from)
            .collect();
        let scalar = select::<f64>(Some(super::super::Kernel::Scalar)).unwrap();
        for k in f64::available() {
            let n = r_len * 3 * p_len;
            let (mut a, mut b) = (vec![0.0; n], vec![0.0; n]);
            k.stage(rows.view(), 0, 3, r_len, p_len, &input, &mut a);
            scalar.stage(rows.view(), 0, 3, r_len, p_len, &input, &mut b);
            assert_eq!(a, b, "{} r_len {r_len}, p_len {p_len}", k.name);
        }
    }
    // The pruned last stage, its row bounds from the three rows merged in one group (on the
    // instances whose vector holds three lanes) or row by row.
    let rows = rows.with_groups(3);
    let scalar = select::<f64>(Some(super::super::Kernel::Scalar)).unwrap();
    for p_len in [5, 40, 130] {
        let input: Vec<f64> = values(3 * p_len, 11).into_iter().map(f64::from).collect();
        let mut bounds = vec![0.0; 3];
        let (mut m, mut ms) = (vec![0.0; 1], vec![0.0; 1]);
        (scalar.last)(
            rows.view(),
            0,
            3,
            InRows::dense(p_len),
            false,
            &input,
            &mut ms,
            &mut bounds,
            None,
        );
        for k in f64::available() {
            (k.last)(
                rows.view(),
                0,
                3,
                InRows::dense(p_len),
                false,
                &input,
                &mut m,
                &mut bounds,
                None,
            );
            assert_eq!(m, ms, "last, {} p_len {p_len}", k.name);
        }
    }
}

/// Rows from `(column, weight)` lists.
fn rows_of(rows: &[&[(u32, f32)]], n_cols: usize) -> RowsBuf<f32> {
    let mut ptr = vec![0u32];
    let (mut col, mut weight) = (Vec::new(), Vec::new());
    for r in rows {
        for &(k, w) in r.iter() {
            col.push(k);
            weight.push(w);
        }
        ptr.push(col.len() as u32);
    }
    RowsBuf::new(ptr, col, weight, n_cols).expect("valid rows")
}

#[test]
fn merged_actions_share_columns_and_keep_each_rows_order() {
    // Unsorted, a repeated column, an empty row.
    let rows = rows_of(
        &[&[(3, 0.1), (5, 0.2)], &[(5, 0.3), (3, 0.4), (5, 0.5)], &[]],
        6,
    );
    let m = stage::Merged::<f32, 3>::new(&rows.view(), 0).expect("few steps");
    let steps: Vec<_> = (0..m.n).map(|s| (m.cols[s], m.masks[s], m.ws[s])).collect();
    assert_eq!(
        steps,
        [
            (3, 0b001, [0.1, 0.0, 0.0]),
            (5, 0b011, [0.2, 0.3, 0.0]),
            (3, 0b010, [0.0, 0.4, 0.0]),
            (5, 0b010, [0.0, 0.5, 0.0]),
        ]
    );
}

#[test]
fn rows_too_long_to_merge_take_the_row_by_row_path_with_the_same_sums() {
    // Six actions of six distinct columns each: 36 steps, past the merged stage's 32.
    let (na, n_k, r_len, p_len) = (6usize, 40usize, 3usize, 37usize);
    let lists: Vec<Vec<(u32, f32)>> = (0..na)
        .map(|a| {
            (0..6)
                .map(|e| ((a * 6 + e) as u32, 0.1 + 0.01 * e as f32))
                .collect()
        })
        .collect();
    let refs: Vec<&[(u32, f32)]> = lists.iter().map(Vec::as_slice).collect();
    let rows = rows_of(&refs, n_k);
    assert!(stage::Merged::<f32, 6>::new(&rows.view(), 0).is_none());
    let input = values(n_k * r_len * p_len, 11);
    for k in f32::available() {
        let mut out = vec![0.0f32; r_len * na * p_len];
        k.stage(rows.view(), 0, na, r_len, p_len, &padded(&input), &mut out);
        for r in 0..r_len {
            for (a, list) in lists.iter().enumerate() {
                for p in 0..p_len {
                    let want = list.iter().fold(0.0f32, |acc, &(c, w)| {
                        w.mul_add(input[(c as usize * r_len + r) * p_len + p], acc)
                    });
                    assert_eq!(out[(r * na + a) * p_len + p].to_bits(), want.to_bits());
                }
            }
        }
    }
}

/// The greedy action is the first holder of the maximum even when a later register block
/// ties the maximum an earlier block found in a higher row: row 1 reaches 1 at lane 3 (index
/// `p_len + 3`), row 0 only at lane 190 (index 190), in a block visited after, where its bound
/// equals the best so far. Skipping rows whose bound only ties the best must not skip it.
#[test]
fn a_tie_in_a_later_register_block_at_a_lower_index_takes_the_action() {
    let (n_k, p_len) = (2usize, 200usize);
    let mut input = vec![0.0f32; n_k * p_len];
    input[..16].fill(0.5); // row 0 below row 1's maximum in the first lanes
    input[190] = 1.0;
    input[p_len + 3] = 1.0;
    for merged in [false, true] {
        let rows = rows_of(&[&[(0, 1.0)], &[(1, 1.0)]], n_k);
        let rows = if merged { rows.with_groups(2) } else { rows };
        let mut bounds = vec![0.0f32; n_k];
        for k in f32::available() {
            let (mut m, mut args) = ([0.0f32], [0u32]);
            let dense = InRows::dense(p_len);
            (k.last)(
                rows.view(),
                0,
                2,
                dense,
                false,
                &input,
                &mut m,
                &mut bounds,
                Some(&mut args),
            );
            assert_eq!(
                (m[0], args[0]),
                (1.0, 190),
                "{} kernels, merged {merged}",
                k.name
            );
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// The pruned last stage on inputs with infinities, values whose sums overflow, and
    /// columns of minus infinity: the row bounds are then not all finite (a step's zero
    /// weight times an infinite bound is NaN), and every instance must give the maxima and
    /// actions of the scalar instance, which bounds and chooses row by row.
    #[test]
    fn pruned_last_stage_with_non_finite_bounds_matches_the_scalar_instance(
        ((n_c, na, n_k, _, p_len), rows) in shaped_rows(),
        seed in any::<u64>(),
        (every, big) in (2usize..6, prop_oneof![Just(f32::INFINITY), Just(3.0e38f32)]),
        (kinds, negative) in (prop::collection::vec(0u8..2, 8), any::<bool>()),
    ) {
        // Positive weights, and infinities of one sign per case: the values themselves are
        // never NaN (the instances need not agree on the maximum of NaN values), while the
        // bounds' lanes may be.
        let weight = rows.weight.iter().map(|&w| w.max(1.0 / 64.0)).collect();
        let rows = RowsBuf::new(rows.ptr.clone(), rows.col.clone(), weight, n_k)
            .expect("valid rows")
            .with_groups(na);
        // Column by column: ordinary values, or among them every few a large one (or all
        // minus infinity, a column whose bound is minus infinity).
        let input: Vec<f32> = values(n_k * p_len, seed)
            .into_iter()
            .enumerate()
            .map(|(i, x)| match (kinds[i / p_len], negative) {
                (1, true) => f32::NEG_INFINITY,
                (1, false) if (i + seed as usize).is_multiple_of(every) => big,
                _ => x,
            })
            .collect();
        let dense = InRows::dense(p_len);
        let scalar = select::<f32>(Some(super::super::Kernel::Scalar)).unwrap();
        let mut bounds = vec![0.0f32; n_k];
        let (mut want, mut want_args) = (vec![0.0f32; n_c], vec![0u32; n_c]);
        (scalar.last)(rows.view(), 0, na, dense, false, &input, &mut want, &mut bounds, Some(&mut want_args));
        for k in f32::available() {
            let (mut m, mut args) = (vec![0.0f32; n_c], vec![0u32; n_c]);
            (k.last)(rows.view(), 0, na, dense, false, &input, &mut m, &mut bounds, Some(&mut args));
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            prop_assert_eq!(bits(&m), bits(&want), "maxima, {} kernels", k.name);
            prop_assert_eq!(&args, &want_args, "actions, {} kernels", k.name);
            (k.last)(rows.view(), 0, na, dense, false, &input, &mut m, &mut bounds, None);
            prop_assert_eq!(bits(&m), bits(&want), "maxima without actions, {} kernels", k.name);
        }
        // And they are the maxima of the full stage, whose first holder is the action.
        for c in 0..n_c {
            let mut full = vec![0.0f32; na * p_len];
            scalar.stage(rows.view(), c * na, na, 1, p_len, &input, &mut full);
            let max = full.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            prop_assert_eq!(want[c].to_bits(), max.to_bits(), "maximum, core {}", c);
            let first = full.iter().position(|&x| x == max).unwrap();
            prop_assert_eq!(want_args[c] as usize, first, "action, core {}", c);
        }
    }
}

/// One value of a change-range test: mostly ordinary, some NaN and zeros of either sign.
fn range_value() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -200.0f32..200.0,
        1 => Just(f32::NAN),
        1 => Just(0.0f32),
        1 => Just(-0.0f32),
    ]
}

proptest! {
    /// The change statistics' range: the lanes, and the AVX2 compilation where the CPU has
    /// one, give the plain minimum and maximum of the differences, NaN differences skipped,
    /// for values and for (value, action) pairs.
    #[test]
    fn diff_range_is_the_plain_minimum_and_maximum(
        (a, b) in (0usize..70).prop_flat_map(|n| (
            prop::collection::vec(range_value(), n),
            prop::collection::vec(-200.0f32..200.0, n),
        )),
    ) {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for (&p, &q) in a.iter().zip(&b) {
            let d = f64::from(p) - f64::from(q);
            if !d.is_nan() {
                lo = lo.min(d);
                hi = hi.max(d);
            }
        }
        let got = diff_range_by(&a, &b, &|&v: &f32| v);
        prop_assert_eq!((got.0 + 0.0, got.1 + 0.0), (lo + 0.0, hi + 0.0));
        let pairs: Vec<(f32, u32)> = a.iter().map(|&v| (v, 7)).collect();
        let got = diff_range_by(&pairs, &b, &|p: &(f32, u32)| p.0);
        prop_assert_eq!((got.0 + 0.0, got.1 + 0.0), (lo + 0.0, hi + 0.0));
        prop_assert_eq!(
            diff_range_lanes(&a, &b, &|&v: &f32| v),
            diff_range_by(&a, &b, &|&v: &f32| v)
        );
    }
}

/// [`Isa::first_equal`] of register blocks of `NV` vectors read from `lanes`, the last vector's
/// first `valid` lanes valid.
fn first_equal_of<I: Isa<f32>, const NV: usize>(
    lanes: &[f32],
    t: f32,
    valid: usize,
) -> Option<usize> {
    assert!(lanes.len() >= NV * I::LANES);
    // SAFETY: every vector read is inside `lanes`; `1 <= valid <= LANES`.
    unsafe {
        let acc: [I::V; NV] = core::array::from_fn(|j| I::load(lanes.as_ptr().add(j * I::LANES)));
        I::first_equal::<NV>(&acc, t, I::mask(valid))
    }
}

#[test]
fn first_equal_takes_the_lowest_valid_lane_and_skips_the_masked_ones() {
    // Three vectors of the portable instance (24 lanes of f32), the last with `valid` lanes
    // valid: the instance's own search (lane-wise minima) against a plain scan.
    const NV: usize = 3;
    let lanes = <portable::Portable<true> as Isa<f32>>::LANES;
    for valid in 1..=lanes {
        let n_valid = (NV - 1) * lanes + valid;
        for hit in [
            None,
            Some(0),
            Some(lanes - 1),
            Some(lanes),
            Some(n_valid - 1),
        ] {
            // Every lane 1 except the hit (7) and the masked lanes (7 too: a masked lane
            // that matches must not be found).
            let mut v = vec![1.0f32; NV * lanes];
            v[n_valid..].fill(7.0);
            if let Some(h) = hit {
                v[h] = 7.0;
            }
            let found = first_equal_of::<portable::Portable<true>, NV>(&v, 7.0, valid);
            assert_eq!(found, hit, "valid {valid}, hit {hit:?}");
            assert_eq!(
                v[..n_valid].iter().position(|&x| x == 7.0),
                hit,
                "the case itself"
            );
            // The default search (bit masks) on the scalar instance, one lane per vector.
            let scalar = first_equal_of::<Scalar, 24>(&v, 7.0, 1);
            assert_eq!(scalar.filter(|&i| i < n_valid), hit, "scalar instance");
        }
    }
}

#[test]
fn first_equal_rows_takes_the_lowest_valid_lane_of_the_lowest_row() {
    // Rows of one portable vector, the first `row_len` lanes valid, the others matching: the
    // instance's search (lane-wise minima) against a plain scan of the valid lanes.
    type P = portable::Portable<true>;
    let lanes = <P as Isa<f32>>::LANES;
    for row_len in 1..=lanes {
        for n_rows in [1, 2, 3, 9, 10] {
            let n_valid = n_rows * row_len;
            for hit in [
                None,
                Some(0),
                Some(row_len - 1),
                Some(n_valid - 1),
                Some(n_valid / 2),
            ] {
                let mut v = vec![7.0f32; n_rows * lanes];
                for r in 0..n_rows {
                    v[r * lanes..r * lanes + row_len].fill(1.0);
                }
                if let Some(h) = hit {
                    v[(h / row_len) * lanes + h % row_len] = 7.0;
                }
                // SAFETY: every vector read is inside `v`; `1 <= row_len <= LANES`.
                let found = unsafe {
                    let rows: Vec<[f32; 8]> = (0..n_rows)
                        .map(|r| P::load(v.as_ptr().add(r * lanes)))
                        .collect();
                    let m = <P as Isa<f32>>::mask(row_len);
                    <P as Isa<f32>>::first_equal_rows(&rows, 7.0, m, row_len)
                };
                assert_eq!(found, hit, "rows of {row_len}, {n_rows} rows");
            }
        }
    }
}

/// [`Isa::reduce_max`] of lanes all minus infinity, for every mask: minus infinity on every
/// instance the CPU runs (AVX-512's masked reduction intrinsic gave the lowest finite value).
#[test]
fn reduce_max_of_minus_infinities_is_minus_infinity() {
    fn check<T: Real + core::fmt::Debug, I: Isa<T>>() {
        for n in 1..=I::LANES {
            // SAFETY: only instances the CPU runs; `1 <= n <= LANES`.
            let got = unsafe { I::reduce_max(I::neg_inf(), I::mask(n)) };
            assert_eq!(got, T::from_f64(f64::NEG_INFINITY), "{n} lanes");
        }
    }
    check::<f32, Scalar>();
    check::<f64, Scalar>();
    check::<f32, portable::Portable<true>>();
    check::<f64, portable::Portable<true>>();
    #[cfg(target_arch = "x86_64")]
    {
        #[cfg(fuzzyq_avx512)]
        if has_avx512() {
            check::<f32, x86::Avx512>();
            check::<f64, x86::Avx512>();
        }
        if has_avx2() {
            check::<f32, x86::Avx2>();
            check::<f64, x86::Avx2>();
        }
    }
}

#[test]
fn an_unavailable_instance_is_refused_saying_why() {
    use crate::options::NamedOption;
    use crate::solver::{Kernel, SolveError};
    for &k in Kernel::ALL {
        let message = SolveError::KernelUnavailable(k).to_string();
        if left_out(k) {
            // A development build on a CPU without the instance (build.rs).
            assert!(select::<f32>(Some(k)).is_none() && select::<f64>(Some(k)).is_none());
            assert!(message.contains("FUZZYQ_KERNELS=all"), "{message}");
        } else {
            assert!(message.starts_with("this CPU cannot run"), "{message}");
        }
    }
}
