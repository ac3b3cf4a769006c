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
