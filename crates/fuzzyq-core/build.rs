//! Which kernel instances to compile.
//!
//! On x86-64 the block path's kernels are compiled four times per scalar type: AVX-512,
//! AVX2, portable (built for AVX2) and scalar. The solver picks, at run time, the fastest one
//! the CPU runs, so every build normally holds all of them. `FUZZYQ_KERNELS` changes that:
//!
//! - unset, empty or `all`: every instance (what a release or a wheel must hold);
//! - `host`: only the instances the CPU running the build can run, where the build is for that
//!   same machine. On a CPU without AVX-512 (with VL and FMA) the AVX-512 instances are left
//!   out; they could not run there, so no test on that machine loses anything, and their code
//!   is over a quarter of this crate's compile time (96 of 346 CPU-seconds of its test build
//!   on a Zen 4; BENCHMARKS.md). `scripts/test.sh` sets it.
//!
//! Emits `cfg(fuzzyq_avx512)` where the AVX-512 instances are compiled.

use std::env;
use std::process::ExitCode;

fn main() -> ExitCode {
    println!("cargo::rustc-check-cfg=cfg(fuzzyq_avx512)");
    println!("cargo::rerun-if-env-changed=FUZZYQ_KERNELS");
    let x86_64 = env::var("CARGO_CFG_TARGET_ARCH").is_ok_and(|a| a == "x86_64");
    let host_only = match env::var("FUZZYQ_KERNELS").as_deref() {
        Err(_) | Ok("" | "all") => false,
        Ok("host") => true,
        Ok(other) => {
            eprintln!("error: FUZZYQ_KERNELS={other:?}: expected `all` or `host`");
            return ExitCode::FAILURE;
        }
    };
    // `host` describes the build machine: it says nothing about another target's CPU.
    let native = env::var("HOST").ok() == env::var("TARGET").ok();
    if x86_64 && !(host_only && native && !host_has_avx512()) {
        println!("cargo::rustc-cfg=fuzzyq_avx512");
    } else if x86_64 {
        println!(
            "cargo::warning=FUZZYQ_KERNELS=host: this CPU has no AVX-512 (F, VL and FMA), \
             so its kernels are left out of this build, which refuses `--kernel avx512` and \
             runs AVX2 at best on any CPU"
        );
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
