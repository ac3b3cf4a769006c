//! A controller's view of fuzzyq-core: static tables, no std, no heap: deciding (memberships,
//! Q evaluation, the greedy and interpolated policies) and learning on board (the additive
//! layout's sample update).
#![no_std]

use core::panic::PanicInfo;

use fuzzyq_core::{ActionSet, JointActions, ProductPartition, q};

#[panic_handler]
fn panic(_: &PanicInfo<'_>) -> ! {
    loop {}
}

static POSITION: [f32; 9] = [-6.0, -3.0, -0.3, -0.1, 0.0, 0.1, 0.3, 3.0, 6.0];
static VELOCITY: [f32; 5] = [-3.0, -1.0, 0.0, 1.0, 3.0];
static FORCES: [f32; 10] = [-2.0, 0.0, -0.2, 0.0, 0.0, 0.0, 0.2, 0.0, 2.0, 0.0];
/// theta for one agent on (s_x, v_x): 45 cores x 5 actions.
static THETA: [f32; 225] = {
    let mut t = [0.0f32; 225];
    let mut i = 0;
    while i < 225 {
        t[i] = ((i * 37) % 101) as f32;
        i += 1;
    }
    t
};
static GREEDY: [u32; 45] = {
    let mut g = [0u32; 45];
    let mut i = 0;
    while i < 45 {
        g[i] = (i % 5) as u32;
        i += 1;
    }
    g
};

/// Memberships, Q evaluation, the greedy and the interpolated decision; returns the greedy
/// action index (or `u32::MAX` on error) and writes the interpolated force.
#[unsafe(no_mangle)]
pub extern "C" fn fuzzyq_decide(s: f32, v: f32, force: &mut f32) -> u32 {
    let Ok(grid) = ProductPartition::try_new(&[&POSITION[..], &VELOCITY[..]]) else {
        return u32::MAX;
    };
    let mut mu = [0.0f32; 9];
    if grid.dim(0).memberships(s, &mut mu).is_err() {
        return u32::MAX;
    }
    let Ok(set) = ActionSet::try_new(&FORCES, 2) else {
        return u32::MAX;
    };
    let Ok(joint) = JointActions::try_new(&[set]) else {
        return u32::MAX;
    };
    let mut qx = [0.0f32; 5];
    let Ok(u) = q::greedy_action(&grid, &THETA, &[s, v], &mut qx) else {
        return u32::MAX;
    };
    let mut h = [0.0f32; 2];
    if q::interpolated_action(&grid, &joint, &GREEDY, &[s, v], &mut h).is_err() {
        return u32::MAX;
    }
    *force = h[0] + mu[0];
    u as u32
}

/// One corrected sample update of the additive layout on the caller's table `phi` (one agent
/// on the (s, v) grid: 45 cores x 5 actions; no heap): returns the TD error, or NaN if the
/// update was refused or the input invalid.
#[unsafe(no_mangle)]
pub extern "C" fn fuzzyq_learn(
    phi: &mut [f32; 225],
    s: f32,
    v: f32,
    action: u32,
    reward: f32,
    s1: f32,
    v1: f32,
) -> f32 {
    use fuzzyq_core::additive::{self, Agent, Update};
    let Ok(grid) = ProductPartition::try_new(&[&POSITION[..], &VELOCITY[..]]) else {
        return f32::NAN;
    };
    let (Ok(cur), Ok(next)) = (grid.active(&[s, v]), grid.active(&[s1, v1])) else {
        return f32::NAN;
    };
    let mut agents = [Agent {
        phi,
        n_actions: 5,
        cur,
        next,
        action: action as usize,
    }];
    match additive::update(Update::Corrected, &mut agents, reward, false, 0.96, 0.1) {
        Ok(Some(delta)) => delta,
        _ => f32::NAN,
    }
}

/// An exported policy read in place from the caller's bytes (for example `include_bytes!`
/// in a `#[repr(align(8))]` static), no heap: the interpolated decision at `(x[0], ..)`, or
/// `false` if the bytes are refused or the state is invalid.
#[unsafe(no_mangle)]
pub extern "C" fn fuzzyq_act_from_export(
    bytes: *const u8,
    len: usize,
    x: &[f32; 4],
    out: &mut [f32; 2],
) -> bool {
    if bytes.is_null() {
        return false;
    }
    // Safety is the caller's (a C interface): `bytes` points at `len` readable bytes.
    #[allow(unsafe_code)]
    let bytes = unsafe { core::slice::from_raw_parts(bytes, len) };
    match fuzzyq_core::view::PolicyView::<f32>::parse(bytes) {
        Ok(view) => view.interpolated_action(x, out).is_ok(),
        Err(_) => false,
    }
}
