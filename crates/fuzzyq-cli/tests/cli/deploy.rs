//! From laptop to robot: a policy trained and exported by the CLI acts in the `no_std`
//! example controller (`examples/embedded-controller`) in a closed loop against the model,
//! and gives the actions and states of `fuzzyq rollout --policy-kind interpolated`, step by
//! step, bit for bit: the DC motor (also as the controller's compiled-in policy, both the
//! binary and the generated Rust module), the pendulum and the paper's point masses. The
//! greedy policy (`fuzzyq rollout`'s default) too: from the export's decision tables for the
//! point masses, and from `V` and the model for the DC motor and the pendulum.

use std::path::Path;

use fuzzyq_core::view::{PolicyView, ViewReal};
use fuzzyq_embedded_controller::{Controller, DC_MOTOR_BIN, Decision, Io, dc_motor, run};
use fuzzyq_sim::io::policy_file::PolicyFile;
use fuzzyq_sim::run::plant::{ModelPlant, Plant};

use super::{fuzzyq, stderr};

/// `bytes` copied to an 8-byte boundary of a fresh buffer (as `Aligned` places them).
fn placed(bytes: &[u8]) -> (Vec<u8>, usize) {
    let mut buf = vec![0u8; bytes.len() + 8];
    let at = buf.as_ptr().align_offset(8);
    buf[at..at + bytes.len()].copy_from_slice(bytes);
    (buf, at)
}

/// A rollout's CSV as rows of numbers (the header skipped; the last row has no action).
fn rows(path: &Path) -> Vec<Vec<f64>> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .skip(1)
        .map(|l| {
            l.split(',')
                .skip(1)
                .filter(|c| !c.is_empty())
                .map(|c| c.parse().unwrap())
                .collect()
        })
        .collect()
}

/// The model as the controller's sensors and actuators, checking each state and action
/// against the rows of a rollout.
struct ModelIo<'a, P> {
    plant: P,
    want: &'a [Vec<f64>],
    /// State length.
    e: usize,
    /// Steps taken.
    k: usize,
}

impl<T: ViewReal, P: Plant> Io<T> for ModelIo<'_, P> {
    fn sense(&mut self, x: &mut [T]) -> bool {
        let (k, e) = (self.k, self.e);
        let state = self.plant.observe().state;
        assert_eq!(state, &self.want[k][..e], "state at step {k}");
        for (to, &from) in x.iter_mut().zip(state) {
            *to = T::from_f64(from);
        }
        k + 1 < self.want.len()
    }

    fn actuate(&mut self, u: &[T], d: Decision) {
        let (k, e) = (self.k, self.e);
        assert_eq!(d, Decision::Policy, "step {k}");
        let u: Vec<f64> = u.iter().map(|v| v.to_f64()).collect();
        assert_eq!(u, &self.want[k][e..e + u.len()], "action at step {k}");
        self.plant.step(&u).unwrap();
        self.k += 1;
    }
}

/// Runs `controller` in the example's control loop against the model of the policy file `fzq`
/// from the CSV's first state, and checks every state and action against the CSV's.
fn same_closed_loop<T: ViewReal>(policy: PolicyView<'_, T>, fzq: &Path, csv: &Path) {
    let fallback = vec![T::ZERO; policy.joint().dim()];
    let controller = Controller::new(policy, &fallback).unwrap();
    same_loop(controller, fzq, csv);
}

fn same_loop<T: ViewReal>(mut controller: Controller<'_, T>, fzq: &Path, csv: &Path) {
    let policy = *controller.view();
    let PolicyFile::Fqi(artifact) = PolicyFile::load(fzq).unwrap() else {
        panic!("not a fuzzy Q-iteration policy")
    };
    let model = artifact.config.build_model().unwrap();
    let mut plant = ModelPlant::new(&model);
    let want = rows(csv);
    let (e, m) = (policy.grid().n_dims(), policy.joint().dim());
    plant.reset(&want[0][..e]).unwrap();
    let (mut x, mut u) = (vec![T::ZERO; e], vec![T::ZERO; m]);
    let steps = want.len() - 1;
    let mut io = ModelIo {
        plant,
        want: &want,
        e,
        k: 0,
    };
    let ran = run(&mut controller, &mut io, &mut x, &mut u);
    assert_eq!(ran, steps as u64);
    assert_eq!(controller.faults(), 0);
}

/// The greedy policy from `view` and the model of the policy file `fzq` (the controller has
/// the model), against the model, checked against the rollout in `csv` step by step.
fn same_greedy_with_model(view: PolicyView<'_, f64>, fzq: &Path, csv: &Path) {
    let PolicyFile::Fqi(artifact) = PolicyFile::load(fzq).unwrap() else {
        panic!("not a fuzzy Q-iteration policy")
    };
    let model = artifact.config.build_model().unwrap();
    let backup = fuzzyq_core::Backup {
        gamma: artifact.config.solver.gamma,
        absorbing_goal: artifact.config.solver.absorbing_goal,
    };
    let mut plant = ModelPlant::new(&model);
    let want = rows(csv);
    let (e, joint) = (view.grid().n_dims(), *view.joint());
    plant.reset(&want[0][..e]).unwrap();
    let mut scratch = vec![0.0; fuzzyq_core::backup::scratch_len(e, joint.dim())];
    let (mut row, mut q) = (vec![0.0; joint.n_joint()], vec![0.0; joint.n_joint()]);
    let mut u = vec![0.0; joint.dim()];
    for (k, w) in want[..want.len() - 1].iter().enumerate() {
        let x = plant.observe().state.to_vec();
        assert_eq!(x, &w[..e], "state at step {k}");
        view.q_values_with_model(&model, backup, &x, &mut scratch, &mut row, &mut q)
            .unwrap();
        joint
            .vector(fuzzyq_core::q::argmax(&q).unwrap(), &mut u)
            .unwrap();
        assert_eq!(u, &w[e..e + u.len()], "action at step {k}");
        plant.step(&u).unwrap();
    }
}

/// Trains with `train` (arguments after `train`), exports the policy in both forms and rolls
/// it out with `rollout` (arguments after the policy) into `r.csv`; returns the binary export.
fn train_export_rollout(d: &Path, train: &[&str], rollout: &[&str]) -> Vec<u8> {
    let mut args = vec!["train"];
    args.extend(train);
    args.extend(["--out", "p.fzq", "-q"]);
    let o = fuzzyq(&args, d);
    assert!(o.status.success(), "{}", stderr(&o));
    for (format, out) in [("bin", "p.bin"), ("rust", "p.rs")] {
        let args = [
            "export", "--policy", "p.fzq", "--format", format, "--out", out,
        ];
        let o = fuzzyq(&args, d);
        assert!(o.status.success(), "{}", stderr(&o));
    }
    let mut args = vec![
        "rollout",
        "--policy",
        "p.fzq",
        "--policy-kind",
        "interpolated",
        "--csv",
        "r.csv",
        "-q",
    ];
    args.extend(rollout);
    let o = fuzzyq(&args, d);
    assert!(o.status.success(), "{}", stderr(&o));
    std::fs::read(d.join("p.bin")).unwrap()
}

#[test]
fn exported_policies_act_in_the_embedded_controller_as_the_cli_rollout() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for env in ["dcmotor", "pendulum"] {
        let o = fuzzyq(&["config", "--env", env, "--preset", "toolbox-demo"], d);
        assert!(o.status.success(), "{}", stderr(&o));
        std::fs::write(d.join("c.toml"), o.stdout).unwrap();
        let exported = train_export_rollout(
            d,
            &["--env", env, "--config", "c.toml"],
            &["--x0=-1,0", "--steps", "150"],
        );
        let (buf, at) = placed(&exported);
        let view = PolicyView::<f64>::parse(&buf[at..]).unwrap();
        same_closed_loop(view, &d.join("p.fzq"), &d.join("r.csv"));
        // The greedy policy (the rollout's default), where the controller has the model.
        let o = fuzzyq(
            &[
                "rollout",
                "--policy",
                "p.fzq",
                "--x0=-1,0",
                "--steps",
                "150",
                "--csv",
                "g.csv",
                "-q",
            ],
            d,
        );
        assert!(o.status.success(), "{}", stderr(&o));
        same_greedy_with_model(view, &d.join("p.fzq"), &d.join("g.csv"));
        if env == "dcmotor" {
            // The controller's compiled-in policy is this one: regenerate it with the
            // commands of examples/embedded-controller/src/lib.rs when this fails.
            let here = Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("../../examples/embedded-controller/policies");
            assert!(
                exported == std::fs::read(here.join("dc_motor.bin")).unwrap()
                    && std::fs::read(d.join("p.rs")).unwrap()
                        == std::fs::read(here.join("dc_motor.rs")).unwrap(),
                "the embedded controller's compiled-in DC motor policy is stale"
            );
            let bundled = PolicyView::<f64>::parse(&DC_MOTOR_BIN.0).unwrap();
            same_closed_loop(bundled, &d.join("p.fzq"), &d.join("r.csv"));
            same_closed_loop(
                dc_motor::view().unwrap(),
                &d.join("p.fzq"),
                &d.join("r.csv"),
            );
        }
    }
    // The paper's two point masses (4.1 million cores, f32, 625 joint actions as u16): the
    // interpolated policy, then the greedy one (the default of `fuzzyq rollout`) from the
    // export's decision tables.
    let exported = train_export_rollout(d, &["--env", "pointmass"], &[]);
    let (buf, at) = placed(&exported);
    let view = PolicyView::<f32>::parse(&buf[at..]).unwrap();
    same_closed_loop(view, &d.join("p.fzq"), &d.join("r.csv"));
    let export = ["export", "--policy", "p.fzq", "--greedy", "--out", "g.bin"];
    let o = fuzzyq(&export, d);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = fuzzyq(&["rollout", "--policy", "p.fzq", "--csv", "g.csv", "-q"], d);
    assert!(o.status.success(), "{}", stderr(&o));
    let exported = std::fs::read(d.join("g.bin")).unwrap();
    let (buf, at) = placed(&exported);
    let view = PolicyView::<f32>::parse(&buf[at..]).unwrap();
    let mut scratch = vec![0u64; view.decision_scratch_len().unwrap()];
    let mut q = vec![0.0f32; view.joint().n_joint()];
    let fallback = [0.0f32; 4];
    let greedy = Controller::greedy(view, &fallback, &mut scratch, &mut q).unwrap();
    same_loop(greedy, &d.join("p.fzq"), &d.join("g.csv"));
}

#[test]
fn the_embedded_controller_falls_back_on_states_it_cannot_act_on() {
    let view = dc_motor::view().unwrap();
    let mut c = Controller::new(view, &[0.0]).unwrap();
    let mut u = [1.0];
    assert!(matches!(
        c.act(&[f64::NAN, 0.0], &mut u),
        Decision::Fallback(_)
    ));
    assert_eq!(u, [0.0]);
    assert!(matches!(c.act(&[0.0], &mut u), Decision::Fallback(_)));
    assert_eq!(c.faults(), 2);
    u = [7.0];
    assert_eq!(c.act(&[0.5, -3.0], &mut u), Decision::Policy);
    assert!(u[0].abs() <= 10.0 && u[0] != 7.0);
    assert!(Controller::new(view, &[0.0, 0.0]).is_err());
    // From the binary form: the same action; bytes that are no policy, or a fallback of the
    // wrong length, are refused.
    let mut b = Controller::from_bytes(&DC_MOTOR_BIN.0, &[0.0]).unwrap();
    let mut w = [7.0f64];
    assert_eq!(b.act(&[0.5, -3.0], &mut w), Decision::Policy);
    assert_eq!(w[0].to_bits(), u[0].to_bits());
    assert_eq!(
        Controller::<f64>::from_bytes(&DC_MOTOR_BIN.0[8..], &[0.0]).unwrap_err(),
        fuzzyq_core::view::ViewError::NotAPolicy
    );
    assert!(matches!(
        Controller::from_bytes(&DC_MOTOR_BIN.0, &[0.0, 0.0]),
        Err(fuzzyq_core::view::ViewError::Actions(_))
    ));
}
