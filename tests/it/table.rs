//! Models known only at the cores (`TabulatedModel`): stored in full or per independent
//! dynamics block, with terminal successors. The block-declared table must give the values of
//! the same model stored in full, which runs the generic backup.

use std::ops::ControlFlow;

use fuzzyq_core::solver::{
    self, BackupPath, BlockTable, Grid, Operator, RowsTable, SolverConfig, TabulatedModel,
};
use fuzzyq_core::{Backup, Model, ProductPartition};

const LEVELS: [f64; 3] = [-1.0, 0.0, 1.0];

/// Two double integrators on a line, agent `i` at `x[2i..2i + 2]` driven by `u[i]`; a
/// transition is terminal when both positions pass 0.9.
fn step(x: &[f64], u: &[f64]) -> (Vec<f64>, f64, bool) {
    let mut next = vec![0.0; 4];
    for i in 0..2 {
        let (p, v) = (x[2 * i], x[2 * i + 1]);
        next[2 * i] = (p + 0.3 * v).clamp(-1.0, 1.0);
        next[2 * i + 1] = (0.9 * v + 0.3 * u[i]).clamp(-1.0, 1.0);
    }
    let terminal = next[0] > 0.9 && next[2] > 0.9;
    let reward = if terminal {
        10.0
    } else {
        -x[0] * x[0] - x[2] * x[2] - 0.05 * (u[0] * u[0] + u[1] * u[1])
    };
    (next, reward, terminal)
}

fn grid() -> Grid<f64> {
    let p: Vec<f64> = (0..7).map(|i| -1.0 + i as f64 / 3.0).collect();
    let v = vec![-1.0, 0.0, 1.0];
    Grid::new(vec![p.clone(), v.clone(), p, v]).expect("grid")
}

fn actions() -> Vec<(Vec<f64>, usize)> {
    vec![(LEVELS.to_vec(), 1), (LEVELS.to_vec(), 1)]
}

/// Every pair's successor, reward and terminal flag, core-major.
fn full(grid: &Grid<f64>) -> (Vec<f64>, Vec<f64>, Vec<(usize, usize)>) {
    let (mut next, mut rewards, mut terminal) = (Vec::new(), Vec::new(), Vec::new());
    let mut x = vec![0.0; 4];
    for d in 0..grid.n_cores() {
        grid.view().core_state(d, &mut x).expect("core");
        for j in 0..9 {
            let u = [LEVELS[j / 3], LEVELS[j % 3]];
            let (n, r, t) = step(&x, &u);
            next.extend(n);
            rewards.push(r);
            if t {
                terminal.push((d, j));
            }
        }
    }
    (next, rewards, terminal)
}

/// The per-agent block tables: each agent's successors at its 7 x 3 block cores.
fn blocks(grid: &Grid<f64>) -> Vec<BlockTable<f64>> {
    (0..2)
        .map(|i| {
            let dims = vec![2 * i, 2 * i + 1];
            let (acts, first) = BlockTable::block_actions(&actions(), &[i]).expect("actions");
            assert_eq!(acts, LEVELS.to_vec());
            let mut next = Vec::new();
            for &p in &grid.cores()[2 * i] {
                for &v in &grid.cores()[2 * i + 1] {
                    for &j in &first {
                        let mut x = vec![0.0; 4];
                        x[2 * i] = p;
                        x[2 * i + 1] = v;
                        let u = [LEVELS[j / 3], LEVELS[j % 3]];
                        let (n, _, _) = step(&x, &u);
                        next.extend([n[2 * i], n[2 * i + 1]]);
                    }
                }
            }
            BlockTable {
                state_dims: dims,
                action_components: vec![i],
                actions: acts,
                next,
            }
        })
        .collect()
}

fn models(terminal_states: bool) -> (TabulatedModel<f64>, TabulatedModel<f64>) {
    let g = grid();
    let (next, rewards, terminal) = full(&g);
    let mut plain = TabulatedModel::new(g.clone(), actions(), next, rewards.clone()).expect("full");
    let mut blocked =
        TabulatedModel::with_blocks(g.clone(), actions(), blocks(&g), rewards).expect("blocks");
    if terminal_states {
        for &(d, j) in &terminal {
            plain.mark_terminal(d, j).expect("pair");
            blocked.mark_terminal(d, j).expect("pair");
        }
        assert!(plain.has_terminal_states() && plain.n_terminal() > 0);
    }
    assert!(blocked.has_blocks() && !plain.has_blocks());
    assert_eq!(blocked.n_blocks(), 2);
    (plain, blocked)
}

#[test]
fn a_block_declared_table_gives_the_values_of_the_full_table() {
    for terminal_states in [false, true] {
        let (plain, blocked) = models(terminal_states);
        let config = SolverConfig {
            gamma: 0.9,
            xi: 1e-10,
            max_sweeps: 2000,
            ..SolverConfig::default()
        };
        let g = grid();
        let a = solver::solve(&plain, &g, &config, |_| ControlFlow::Continue(())).expect("full");
        let b =
            solver::solve(&blocked, &g, &config, |_| ControlFlow::Continue(())).expect("blocks");
        assert_eq!(a.path, BackupPath::Generic);
        assert_eq!(b.path, BackupPath::Block);
        for (x, y) in a.v.iter().zip(&b.v) {
            assert!((x - y).abs() <= 1e-9 * x.abs().max(1.0), "{x} vs {y}");
        }
        // Q-values at off-core states agree too (decisions use them).
        let backup = Backup::discounted(0.9);
        let op_a = Operator::new(&plain, g.view(), backup, BackupPath::Auto).expect("op");
        let op_b = Operator::new(&blocked, g.view(), backup, BackupPath::Auto).expect("op");
        let (mut qa, mut qb) = (vec![0.0; 9], vec![0.0; 9]);
        for k in 0..50 {
            let t = k as f64 / 50.0;
            let x = [t * 1.8 - 0.9, 0.7 - t, 0.3 * t, -0.5 + t];
            op_a.q_values(&a.v, &x, &mut qa).expect("q");
            op_b.q_values(&a.v, &x, &mut qb).expect("q");
            for (p, q) in qa.iter().zip(&qb) {
                assert!(
                    (p - q).abs() <= 1e-9 * p.abs().max(1.0),
                    "{p} vs {q} at {x:?}"
                );
            }
        }
    }
}

#[test]
fn terminal_successors_end_the_return() {
    let (with, _) = models(true);
    let (without, _) = models(false);
    let config = SolverConfig {
        gamma: 0.9,
        xi: 1e-8,
        max_sweeps: 2000,
        ..SolverConfig::default()
    };
    let g = grid();
    let a = solver::solve(&with, &g, &config, |_| ControlFlow::Continue(())).expect("terminal");
    let b = solver::solve(&without, &g, &config, |_| ControlFlow::Continue(())).expect("plain");
    // The last core (both agents at 1 moving right) ends its episodes at once with terminal
    // states; without them it collects the goal reward again and again.
    let last = g.n_cores() - 1;
    assert!(
        b.v[last] > a.v[last] + 5.0,
        "{} vs {}",
        b.v[last],
        a.v[last]
    );
    assert!(with.is_terminal(&[1.0, 1.0, 1.0, 1.0]));
    assert!(!with.is_terminal(&[0.0, 0.0, 0.0, 0.0]));
}

#[test]
fn malformed_block_tables_are_refused() {
    let g = grid();
    let (_, rewards, _) = full(&g);
    let mut bad = blocks(&g);
    bad[1].state_dims = vec![1, 3];
    assert!(TabulatedModel::with_blocks(g.clone(), actions(), bad, rewards.clone()).is_err());
    let mut short = blocks(&g);
    short[0].next.pop();
    assert!(TabulatedModel::with_blocks(g.clone(), actions(), short, rewards.clone()).is_err());
    let mut actions_wrong = blocks(&g);
    actions_wrong[0].actions = vec![1.0, 0.0, -1.0];
    assert!(TabulatedModel::with_blocks(g.clone(), actions(), actions_wrong, rewards).is_err());
}

/// The block tables as rows: each block successor's memberships over its block's cores (a
/// deterministic model is the one-point case of a learned distribution).
fn rows(grid: &Grid<f64>) -> Vec<RowsTable<f64>> {
    blocks(grid)
        .into_iter()
        .map(|t| {
            let cores: Vec<&[f64]> = t.state_dims.iter().map(|&d| &grid.cores()[d][..]).collect();
            let part = ProductPartition::try_new(&cores).expect("block partition");
            let (mut ptr, mut col, mut weight) = (vec![0u32], Vec::new(), Vec::new());
            for succ in t.next.chunks(2) {
                part.active(succ).expect("in range").for_each(|c, mu| {
                    col.push(c as u32);
                    weight.push(mu);
                });
                ptr.push(col.len() as u32);
            }
            RowsTable {
                state_dims: t.state_dims,
                action_components: t.action_components,
                actions: t.actions,
                ptr,
                col,
                weight,
            }
        })
        .collect()
}

#[test]
fn a_table_of_rows_gives_the_values_of_its_successors() {
    let g = grid();
    let (_, rewards, _) = full(&g);
    let blocked = TabulatedModel::with_blocks(g.clone(), actions(), blocks(&g), rewards.clone())
        .expect("blocks");
    let learned =
        TabulatedModel::with_block_rows(g.clone(), actions(), rows(&g), rewards).expect("rows");
    assert!(learned.has_blocks() && learned.block_rows(1).is_some());
    let config = SolverConfig {
        gamma: 0.9,
        xi: 1e-10,
        max_sweeps: 2000,
        ..SolverConfig::default()
    };
    let a = solver::solve(&blocked, &g, &config, |_| ControlFlow::Continue(())).expect("blocks");
    let b = solver::solve(&learned, &g, &config, |_| ControlFlow::Continue(())).expect("rows");
    assert_eq!(b.path, BackupPath::Block);
    for (x, y) in a.v.iter().zip(&b.v) {
        assert!((x - y).abs() <= 1e-9 * x.abs().max(1.0), "{x} vs {y}");
    }
    assert_eq!(a.greedy, b.greedy);
    // Rows have no successors: a step is NaN, a successor an error naming why.
    let mut next = [0.0; 4];
    learned.step(&[0.0; 4], &[0.0, 0.0], &mut next);
    assert!(next.iter().all(|v| v.is_nan()));
    let e = learned.successor(0, 0, &mut next).unwrap_err();
    assert!(e.to_string().contains("block tables"), "{e}");
    // The generic path cannot read rows.
    let generic = SolverConfig {
        path: BackupPath::Generic,
        ..config
    };
    assert!(solver::solve(&learned, &g, &generic, |_| ControlFlow::Continue(())).is_err());
}

#[test]
fn a_table_of_rows_is_checked() {
    let g = grid();
    let (_, rewards, _) = full(&g);
    let mut short = rows(&g);
    short[0].ptr.pop();
    assert!(TabulatedModel::with_block_rows(g.clone(), actions(), short, rewards.clone()).is_err());
    let mut overlap = rows(&g);
    overlap[1].state_dims = vec![0, 1];
    assert!(
        TabulatedModel::with_block_rows(g.clone(), actions(), overlap, rewards.clone()).is_err()
    );
    let mut nan = rows(&g);
    nan[0].weight[0] = f64::NAN;
    assert!(TabulatedModel::with_block_rows(g, actions(), nan, rewards).is_err());
}
