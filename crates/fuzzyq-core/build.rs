//! Which kernel instances to compile.
//!
//! On x86-64 the block path's kernels are compiled four times per scalar type: AVX-512,
//! AVX2, portable (built for AVX2) and scalar. The solver picks, at run time, the fastest one
//! the CPU runs. A release build (a profile that inherits `release`: `cargo install`, the
//! wheels, the benchmarks) holds every instance, wherever it is built. A development build
//! (`dev`, `test` and the profiles that inherit them) for the machine that builds it holds
//! only the instances that machine's CPU runs: on a CPU without AVX-512 (with VL and FMA) the
//! AVX-512 instances, which nothing built there could run, are left out. They are over a
//! quarter of this crate's compile time (96 of 346 CPU-seconds of its test build on a Zen 4;
//! BENCHMARKS.md, "CI on two cores").
//!
//! `FUZZYQ_KERNELS` overrides the choice: `all` (every instance; `.ci/run` lints that way) or
//! `host` (only those the building CPU runs, for a build for that same machine).
//!
//! Emits `cfg(fuzzyq_avx512)` where the AVX-512 instances are compiled.

use std::env;
use std::process::ExitCode;

fn main() -> ExitCode {
    println!("cargo::rustc-check-cfg=cfg(fuzzyq_avx512)");
    println!("cargo::rerun-if-env-changed=FUZZYQ_KERNELS");
    let x86_64 = env::var("CARGO_CFG_TARGET_ARCH").is_ok_and(|a| a == "x86_64");
    // `PROFILE` is `debug` for every profile rooted in `dev`, `release` for the others.
    let development = env::var("PROFILE").is_ok_and(|p| p == "debug");
    let host_only = match env::var("FUZZYQ_KERNELS").as_deref() {
        Err(_) | Ok("") => development,
        Ok("all") => false,
        Ok("host") => true,
        Ok(other) => {
            eprintln!("error: FUZZYQ_KERNELS={other:?}: expected `all` or `host`");
            return ExitCode::FAILURE;
        }
    };
    // The building CPU says nothing about another target's.
    let native = env::var("HOST").ok() == env::var("TARGET").ok();
    if x86_64 && !(host_only && native && !host_has_avx512()) {
        println!("cargo::rustc-cfg=fuzzyq_avx512");
    }
    ExitCode::SUCCESS
}

/// The features `has_avx512` (src/solver/simd/mod.rs) asks for at run time.
#[cfg(target_arch = "x86_64")]
fn host_has_avx512() -> bool {
    std::arch::is_x86_feature_detected!("avx512f")
        && std::arch::is_x86_feature_detected!("avx512vl")
        && std::arch::is_x86_feature_detected!("fma")
}

#[cfg(not(target_arch = "x86_64"))]
fn host_has_avx512() -> bool {
    false
}
