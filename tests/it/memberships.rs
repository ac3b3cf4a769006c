//! Property tests of the fuzzy partitions and policies.

use fuzzyq_core::{ActionSet, JointActions, Partition, ProductPartition, q};
use proptest::prelude::*;

/// Strictly increasing cores: a start and positive gaps.
fn cores(max_len: usize) -> impl Strategy<Value = Vec<f64>> {
    (
        -10.0..10.0f64,
        prop::collection::vec(0.01..5.0f64, 1..max_len),
    )
        .prop_map(|(start, gaps)| {
            let mut c = vec![start];
            for g in gaps {
                let last = *c.last().unwrap();
                c.push(last + g);
            }
            c
        })
}

proptest! {
    #[test]
    fn memberships_sum_to_one_and_stay_in_range(c in cores(12), x in -30.0..30.0f64) {
        let p = Partition::try_from_cores(&c).unwrap();
        let mut mu = vec![0.0; c.len()];
        p.memberships(x, &mut mu).unwrap();
        let sum: f64 = mu.iter().sum();
        prop_assert!((sum - 1.0).abs() < 1e-12, "sum {sum}");
        prop_assert!(mu.iter().all(|&m| (0.0..=1.0).contains(&m)));
        prop_assert!(mu.iter().filter(|&&m| m > 0.0).count() <= 2);
        for (k, &m) in mu.iter().enumerate() {
            prop_assert_eq!(m, p.membership(k, x));
        }
    }

    #[test]
    fn memberships_are_exact_at_cores(c in cores(12), pick in any::<prop::sample::Index>()) {
        let p = Partition::try_from_cores(&c).unwrap();
        let k = pick.index(c.len());
        let mut mu = vec![0.0; c.len()];
        p.memberships(c[k], &mut mu).unwrap();
        for (j, &m) in mu.iter().enumerate() {
            prop_assert_eq!(m, if j == k { 1.0 } else { 0.0 });
        }
    }

    #[test]
    fn values_outside_saturate(c in cores(8), beyond in 0.0..100.0f64) {
        let p = Partition::try_from_cores(&c).unwrap();
        prop_assert_eq!(p.membership(0, c[0] - beyond), 1.0);
        prop_assert_eq!(p.membership(c.len() - 1, c[c.len() - 1] + beyond), 1.0);
    }

    #[test]
    fn product_weights_sum_to_one(
        dims in prop::collection::vec(cores(5), 1..6),
        xs in prop::collection::vec(-15.0..15.0f64, 6),
    ) {
        let views: Vec<&[f64]> = dims.iter().map(Vec::as_slice).collect();
        let g = ProductPartition::try_new(&views).unwrap();
        let x = &xs[..dims.len()];
        let a = g.active(x).unwrap();
        let mut sum = 0.0;
        let mut count = 0;
        let mut last = None;
        a.for_each(|d, w| {
            sum += w;
            count += 1;
            assert!(last.is_none_or(|l| d > l), "increasing flat order");
            last = Some(d);
            // The product weight is the membership of the core.
            assert!((g.membership(d, x).unwrap() - w).abs() < 1e-12);
        });
        prop_assert!((sum - 1.0).abs() < 1e-12);
        prop_assert_eq!(count, a.len());
        prop_assert!(count <= 1 << dims.len());
    }

    #[test]
    fn product_cores_are_exact(
        dims in prop::collection::vec(cores(4), 1..5),
        pick in any::<prop::sample::Index>(),
    ) {
        let views: Vec<&[f64]> = dims.iter().map(Vec::as_slice).collect();
        let g = ProductPartition::try_new(&views).unwrap();
        let d = pick.index(g.n_cores());
        let mut x = vec![0.0; dims.len()];
        g.core_state(d, &mut x).unwrap();
        let a = g.active(&x).unwrap();
        prop_assert_eq!(a.len(), 1);
        a.for_each(|k, w| {
            assert_eq!((k, w), (d, 1.0));
        });
    }

    #[test]
    fn interpolated_action_stays_in_the_hull(
        x in -2.0..2.0f64, y in -2.0..2.0f64,
        greedy in prop::collection::vec(0u32..9, 9),
    ) {
        let c = [-1.0, 0.0, 1.0];
        let g = ProductPartition::try_new(&[&c[..], &c[..]]).unwrap();
        let levels = [-2.0, 0.0, 2.0];
        let set = ActionSet::try_new(&levels, 1).unwrap();
        let j = JointActions::try_new(&[set, set]).unwrap();
        let mut out = [0.0; 2];
        q::interpolated_action(&g, &j, &greedy, &[x, y], &mut out).unwrap();
        // Inside the hull of the actions, up to the rounding of weights that sum to 1.
        let lim = 2.0 * (1.0 + 4.0 * f64::EPSILON);
        prop_assert!(out.iter().all(|v| v.abs() <= lim), "{out:?}");
    }
}

#[test]
fn bad_inputs_are_typed_errors() {
    let c = [0.0f32, 1.0];
    let g = ProductPartition::try_new(&[&c[..], &c[..]]).unwrap();
    assert!(g.active(&[0.5]).is_err());
    assert!(g.active(&[0.5, f32::NAN]).is_err());
    let mut mu = [0.0f32; 3];
    assert!(g.dim(0).memberships(0.5, &mut mu).is_err());
    let theta = [0.0f32; 7];
    let mut q = [0.0f32; 2];
    assert!(q::q_values(&g, &theta, &[0.0, 0.0], &mut q).is_err());
    let bad: [&[f32]; 1] = [&[1.0, 0.5]];
    let e = ProductPartition::try_new(&bad).unwrap_err();
    assert_eq!(
        e.to_string(),
        "state variable 0: cores must increase strictly, but core 1 does not exceed core 0"
    );
}

proptest! {
    /// A crisp partition puts the whole membership on one nearest core.
    #[test]
    fn crisp_membership_is_the_nearest_core(c in cores(12), x in -30.0..30.0f64) {
        use fuzzyq_core::Membership;
        let p = Partition::try_from_cores(&c).unwrap().with_membership(Membership::Crisp);
        let mut mu = vec![0.0; c.len()];
        p.memberships(x, &mut mu).unwrap();
        let ones: Vec<usize> = (0..c.len()).filter(|&k| mu[k] == 1.0).collect();
        prop_assert_eq!(ones.len(), 1);
        prop_assert!(mu.iter().all(|&m| m == 0.0 || m == 1.0));
        let k = ones[0];
        for (j, &cj) in c.iter().enumerate() {
            prop_assert!((x - c[k]).abs() <= (x - cj).abs() + 1e-12, "core {k} is not nearest (core {j})");
        }
        let grid = ProductPartition::try_new(&[&c[..], &c[..]]).unwrap().with_membership(Membership::Crisp);
        let active = grid.active(&[x, x]).unwrap();
        prop_assert_eq!(active.len(), 1);
        active.for_each(|d, w| {
            assert_eq!((d, w), (k * c.len() + k, 1.0));
        });
    }
}

/// Per agent: `levels` per component, every combination (`dim` components).
fn agent_actions(levels: &[f32], dim: usize) -> Vec<f32> {
    let n = levels.len().pow(dim as u32);
    let mut out = Vec::with_capacity(n * dim);
    for j in 0..n {
        let mut r = j;
        let mut a = vec![0.0; dim];
        for c in (0..dim).rev() {
            a[c] = levels[r % levels.len()];
            r /= levels.len();
        }
        out.extend(a);
    }
    out
}

/// The per-component range of an agent's action set.
fn component_range(set: &ActionSet<'_, f32>, k: usize) -> (f32, f32) {
    (0..set.n_actions())
        .map(|j| set.action(j)[k])
        .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), c| {
            (lo.min(c), hi.max(c))
        })
}

/// Strictly increasing `f32` cores.
fn cores_f32(max_len: usize) -> impl Strategy<Value = Vec<f32>> {
    cores(max_len).prop_map(|c| {
        let mut out: Vec<f32> = Vec::with_capacity(c.len());
        for v in c {
            let v = v as f32;
            if out.last().is_none_or(|&l| v > l) {
                out.push(v);
            }
        }
        out
    })
}

/// A state of `f32` memberships whose product weights sum to more than 1: the weighted
/// average of an action at the upper bound exceeds it unless clamped.
#[test]
fn interpolated_action_is_clamped_where_memberships_sum_above_one() {
    let c: Vec<f32> = vec![-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0];
    let v: Vec<f32> = vec![-3.0, -1.0, 0.0, 1.0, 3.0];
    let g = ProductPartition::try_new(&[&c[..], &c[..], &v[..], &v[..]]).unwrap();
    let levels = [-2.0f32, -0.2, 0.0, 0.2, 2.0];
    let acts = agent_actions(&levels, 2);
    let set = ActionSet::try_new(&acts, 2).unwrap();
    let j = JointActions::try_new(&[set]).unwrap();
    // Every core's greedy action is (2, 2), the upper bound of both components.
    let top = (acts.len() / 2 - 1) as u32;
    let greedy = vec![top; g.n_cores()];
    let mut out = [0.0f32; 2];
    let mut found = 0;
    let mut s: u64 = 0x9E37_79B9_7F4A_7C15;
    for _ in 0..20_000 {
        let x: Vec<f32> = (0..4)
            .map(|d| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                let u = (s >> 11) as f32 / (1u64 << 53) as f32;
                if d < 2 { 12.0 * u - 6.0 } else { 6.0 * u - 3.0 }
            })
            .collect();
        // The unclamped average, as eq 22 sums it.
        let mut raw = 0.0f32;
        g.active(&x).unwrap().for_each(|_, w| raw += w * 2.0);
        if raw > 2.0 {
            found += 1;
            q::interpolated_action(&g, &j, &greedy, &x, &mut out).unwrap();
            assert_eq!(out, [2.0, 2.0], "at {x:?} (unclamped {raw})");
        }
    }
    assert!(found > 0, "no state whose memberships sum above 1");
}

proptest! {
    /// Interpolated actions stay within each component's range over its agent's actions, for
    /// random grids, states and greedy tables (in `f32`, where the memberships' rounding
    /// shows most), with per-agent action sets of different ranges.
    #[test]
    fn interpolated_actions_stay_within_the_bounds(
        c0 in cores_f32(6), c1 in cores_f32(6), c2 in cores_f32(4),
        u in prop::collection::vec(-0.2..1.2f64, 3),
        levels0 in prop::collection::vec(-5.0..5.0f32, 1..5),
        levels1 in prop::collection::vec(-5.0..5.0f32, 1..4),
        greedy_seed in any::<u64>(),
        extremes in any::<bool>(),
    ) {
        let g = ProductPartition::try_new(&[&c0[..], &c1[..], &c2[..]]).unwrap();
        let a0 = agent_actions(&levels0, 2);
        let a1 = agent_actions(&levels1, 1);
        let s0 = ActionSet::try_new(&a0, 2).unwrap();
        let s1 = ActionSet::try_new(&a1, 1).unwrap();
        let j = JointActions::try_new(&[s0, s1]).unwrap();
        let m = j.n_joint() as u64;
        let mut s = greedy_seed | 1;
        let greedy: Vec<u32> = (0..g.n_cores())
            .map(|_| {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                // Either random actions or all at the table's first or last action.
                if extremes { if s % 2 == 0 { 0 } else { (m - 1) as u32 } } else { (s % m) as u32 }
            })
            .collect();
        let x: Vec<f32> = [&c0, &c1, &c2]
            .iter()
            .zip(&u)
            .map(|(c, &t)| {
                let (lo, hi) = (c[0] as f64, c[c.len() - 1] as f64);
                (lo + (hi - lo) * t) as f32
            })
            .collect();
        let mut out = [0.0f32; 3];
        q::interpolated_action(&g, &j, &greedy, &x, &mut out).unwrap();
        for (k, &o) in out.iter().enumerate() {
            let (set, comp) = if k < 2 { (s0, k) } else { (s1, 0) };
            let (lo, hi) = component_range(&set, comp);
            prop_assert!(lo <= o && o <= hi, "component {k}: {o} outside [{lo}, {hi}]");
        }
    }
}
