//! An example robot controller built on `fuzzyq-core` alone: `#![no_std]`, no allocator, a
//! trained policy compiled into the program, one decision per sample time.
//!
//! # From laptop to robot
//! 1. Train and export on the laptop:
//!    `fuzzyq train --env dcmotor --preset toolbox-demo --out p.fzq`, then
//!    `fuzzyq export --policy p.fzq --out dc_motor.bin` (the binary format) or
//!    `fuzzyq export --policy p.fzq --format rust --out dc_motor.rs` (a module of `static`
//!    arrays).
//! 2. Include it: `&Aligned(*include_bytes!("dc_motor.bin"))` checked by
//!    [`PolicyView::parse`], or `mod dc_motor;` and its `view()`. Both are here:
//!    [`DC_MOTOR_BIN`] and [`dc_motor`], the same policy.
//! 3. Act: a [`Controller`] holds the view and gives the interpolated policy's action for
//!    each measured state ([`Controller::new`]), or the greedy policy's from an export with
//!    `--greedy` on buffers the caller provides ([`Controller::greedy`]). [`run`] is the
//!    control loop (sense, act, actuate through [`Io`]) that the host tests drive against the
//!    model and the firmware entry point drives from C.
//!
//! The firmware build (`--features firmware`, as a static library with `panic = "abort"`)
//! adds a panic handler and `fuzzyq_dc_motor_loop`, a C entry point; it links without std and
//! without a global allocator, which `scripts/test.sh` checks.
#![no_std]

use fuzzyq_core::EvalError;
use fuzzyq_core::view::{Aligned, DecideError, PolicyView, ViewError, ViewReal};

/// The DC motor policy (`fuzzyq train --env dcmotor --preset toolbox-demo`) as a generated
/// module of `static` arrays (`fuzzyq export --format rust`).
#[rustfmt::skip]
#[path = "../policies/dc_motor.rs"]
pub mod dc_motor;

/// The same DC motor policy in the binary format (`fuzzyq export`), at an 8-byte boundary.
pub static DC_MOTOR_BIN: &Aligned<[u8]> = &Aligned(*include_bytes!("../policies/dc_motor.bin"));

/// What a controller did at one step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Decision {
    /// The policy's action.
    Policy,
    /// The fallback action: the policy could not act on the measured state (for example a
    /// failed sensor's NaN, or a state of the wrong length).
    Fallback(DecideError),
}

/// Which of the paper's policies a controller follows.
#[derive(Debug)]
enum Policy<'a, T> {
    /// Eq 22: the memberships' weighted average of the active cores' greedy actions.
    Interpolated,
    /// Eq 7: the joint action maximising `Q(x, .)`, from the export's decision tables, on the
    /// caller's buffers.
    Greedy {
        scratch: &'a mut [u64],
        q: &'a mut [T],
    },
}

/// A policy acting on measured states, with a fallback action for states it cannot act on: a
/// control loop never stops on a bad measurement.
#[derive(Debug)]
pub struct Controller<'a, T> {
    view: PolicyView<'a, T>,
    policy: Policy<'a, T>,
    fallback: &'a [T],
    faults: u32,
}

impl<'a, T: ViewReal> Controller<'a, T> {
    /// A controller following the interpolated policy of `view`, writing `fallback` (one
    /// value per action component, for example zero torque) when a state cannot be acted on.
    pub fn new(view: PolicyView<'a, T>, fallback: &'a [T]) -> Result<Self, EvalError> {
        fuzzyq_core::error::check_len("fallback action", view.joint().dim(), fallback.len())?;
        Ok(Self {
            view,
            policy: Policy::Interpolated,
            fallback,
            faults: 0,
        })
    }

    /// A controller following the greedy policy of `view` (exported with `--greedy`) on the
    /// caller's buffers: `scratch` of at least `view.decision_scratch_len()` words and `q` of
    /// one value per joint action (for example `static` arrays sized at build time).
    pub fn greedy(
        view: PolicyView<'a, T>,
        fallback: &'a [T],
        scratch: &'a mut [u64],
        q: &'a mut [T],
    ) -> Result<Self, DecideError> {
        let needed = view.decision_scratch_len().ok_or(DecideError::NoTables)?;
        if scratch.len() < needed {
            return Err(DecideError::Eval(EvalError::Length {
                what: "decision scratch (u64 words)",
                expected: needed,
                found: scratch.len(),
            }));
        }
        fuzzyq_core::error::check_len("Q-values", view.joint().n_joint(), q.len())?;
        let mut c = Self::new(view, fallback)?;
        c.policy = Policy::Greedy { scratch, q };
        Ok(c)
    }

    /// A controller acting with the exported policy in `bytes` (see [`Self::new`]).
    pub fn from_bytes(bytes: &'a [u8], fallback: &'a [T]) -> Result<Self, ViewError> {
        let policy = PolicyView::parse(bytes)?;
        Self::new(policy, fallback).map_err(ViewError::Actions)
    }

    /// The exported policy.
    #[must_use]
    pub fn view(&self) -> &PolicyView<'a, T> {
        &self.view
    }

    /// Steps that fell back so far.
    #[must_use]
    pub fn faults(&self) -> u32 {
        self.faults
    }

    /// One decision: the policy's action at the measured state `x` into `u`
    /// (`view().joint().dim()` values), or the fallback action.
    pub fn act(&mut self, x: &[T], u: &mut [T]) -> Decision {
        let acted = match &mut self.policy {
            Policy::Interpolated => self
                .view
                .interpolated_action(x, u)
                .map_err(DecideError::Eval),
            Policy::Greedy { scratch, q } => self.view.greedy_action(x, scratch, q, u).map(|_| ()),
        };
        match acted {
            Ok(()) => Decision::Policy,
            Err(e) => {
                self.faults = self.faults.saturating_add(1);
                for (o, &f) in u.iter_mut().zip(self.fallback) {
                    *o = f;
                }
                Decision::Fallback(e)
            }
        }
    }
}

/// What a control loop talks to: the robot's sensors and actuators.
pub trait Io<T> {
    /// Fills `x` with the measured state; `false` ends the loop.
    fn sense(&mut self, x: &mut [T]) -> bool;
    /// Applies the action `u` (`decision` says whether it is the policy's or the fallback).
    fn actuate(&mut self, u: &[T], decision: Decision);
}

/// The control loop: while `io` senses a state, the controller decides and `io` actuates.
/// `x` and `u` are the caller's buffers (state and action lengths); returns the steps run.
pub fn run<T: ViewReal>(
    controller: &mut Controller<'_, T>,
    io: &mut impl Io<T>,
    x: &mut [T],
    u: &mut [T],
) -> u64 {
    let mut steps = 0;
    while io.sense(x) {
        let d = controller.act(x, u);
        io.actuate(u, d);
        steps += 1;
    }
    steps
}

#[cfg(feature = "firmware")]
mod firmware {
    //! What a final `no_std` artifact needs: a panic handler (the controller does not panic
    //! on any input; this is the linker's requirement), and an entry point for C.

    use super::{Controller, Decision, Io, dc_motor, run};

    /// The C program's callbacks.
    struct CIo {
        sense: extern "C" fn(&mut [f64; 2]) -> bool,
        actuate: extern "C" fn(f64, i32),
    }

    impl Io<f64> for CIo {
        fn sense(&mut self, x: &mut [f64]) -> bool {
            let mut measured = [0.0; 2];
            let go = (self.sense)(&mut measured);
            for (to, from) in x.iter_mut().zip(measured) {
                *to = from;
            }
            go
        }

        fn actuate(&mut self, u: &[f64], decision: Decision) {
            let voltage = u.first().copied().unwrap_or(0.0);
            (self.actuate)(voltage, i32::from(decision != Decision::Policy));
        }
    }

    #[panic_handler]
    fn panic(_: &core::panic::PanicInfo<'_>) -> ! {
        loop {}
    }

    /// The DC motor's control loop for a C program: `sense(x)` fills the angle and angular
    /// velocity and returns whether to go on, `actuate(voltage, fallback)` applies the
    /// action (`fallback` is 1 when the state could not be acted on and the voltage is 0).
    /// Returns the steps run, or -1 if the compiled-in policy is invalid.
    #[allow(unsafe_code)] // `no_mangle` exports the symbol the C program links against.
    #[unsafe(no_mangle)]
    pub extern "C" fn fuzzyq_dc_motor_loop(
        sense: extern "C" fn(&mut [f64; 2]) -> bool,
        actuate: extern "C" fn(f64, i32),
    ) -> i64 {
        let Ok(view) = dc_motor::view() else {
            return -1;
        };
        let Ok(mut controller) = Controller::new(view, &[0.0]) else {
            return -1;
        };
        let mut io = CIo { sense, actuate };
        let steps = run(&mut controller, &mut io, &mut [0.0; 2], &mut [0.0; 1]);
        i64::try_from(steps).unwrap_or(i64::MAX)
    }
}
