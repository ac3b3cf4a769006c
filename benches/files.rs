//! Policy files as `fuzzyq train` writes them at the end of a run: the container and its
//! postcard payload encoded to a writer that keeps nothing (the encoding and the checksum;
//! the disk is the host's), on the shapes of the paper's point masses (4,100,625 cores,
//! greedy joint actions below 625: one or two bytes each) and of the paper's Khepera robots
//! (37,662,769 cores, 16 joint actions: a byte each). `V` and the greedy actions are
//! seeded pseudo-random: the bytes of a trained policy take the same time. And the same
//! files loaded again (`policy_read`: decoded and checked), from memory, from a file as
//! `PolicyFile::load` reads it (`_load`: decoded as it is read), and from the file read
//! whole first (`_load_whole`).
#![allow(missing_docs)]

use std::hint::black_box;
use std::io::{Seek, SeekFrom, Write};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use fuzzyq_benches::values;
use fuzzyq_sim::io::policy_file::{PolicyFile, Values};
use fuzzyq_sim::model::EnvKind;
use fuzzyq_sim::{PolicyArtifact, TrainConfig};

/// A writer that counts what it is given and keeps nothing.
struct Discard(u64);

impl Write for Discard {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0 += buf.len() as u64;
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for Discard {
    fn seek(&mut self, _: SeekFrom) -> std::io::Result<u64> {
        Ok(self.0)
    }
}

/// A trained policy of a small grid (its configuration and summary) holding `n` values and
/// greedy actions below `joint_actions` instead of its own.
fn policy(small: &PolicyArtifact, n: usize, joint_actions: u32) -> PolicyFile {
    let mut s = 0x9e37_79b9_7f4a_7c15u64;
    let greedy = (0..n)
        .map(|_| {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s % u64::from(joint_actions)) as u32
        })
        .collect();
    PolicyFile::Fqi(PolicyArtifact {
        values: Values::F32(values(n, 30.0)),
        greedy,
        ..small.clone()
    })
}

fn bench_files(c: &mut Criterion) {
    let mut config = TrainConfig::default();
    config.grid.position_cores = vec![-6.0, 0.0, 6.0];
    config.grid.velocity_cores = vec![-3.0, 0.0, 3.0];
    let small = fuzzyq_sim::train::train(&config, |_| std::ops::ControlFlow::Continue(())).unwrap();
    let mut g = c.benchmark_group("policy_write");
    g.sample_size(20);
    for (name, n, m) in [("paper", 4_100_625, 625), ("khepera", 37_662_769, 16)] {
        let file = policy(&small, n, m);
        let bytes = file.write_to(Discard(0)).unwrap().0;
        g.throughput(Throughput::Bytes(bytes));
        g.bench_function(name, |b| {
            b.iter(|| black_box(file.write_to(Discard(0)).unwrap().0));
        });
    }
    g.finish();
    // Loading it again, decoded and checked: from memory; from a file (page-cached) as
    // `PolicyFile::load` reads it, decoded as it is read; and from the file read whole first.
    let mut g = c.benchmark_group("policy_read");
    g.sample_size(10);
    let path = std::env::temp_dir().join(format!("fuzzyq-bench-{}.fzq", std::process::id()));
    for (name, env, m) in [
        ("paper", EnvKind::Pointmass, 625),
        ("khepera", EnvKind::Khepera, 16),
    ] {
        // The environment's own configuration, so that the file checks out.
        let mut own = small.clone();
        own.config = TrainConfig::default_for(env).unwrap();
        let file = policy(&own, own.config.n_cores(), m);
        let bytes = file.to_bytes().unwrap();
        file.save(&path).unwrap();
        g.throughput(Throughput::Bytes(bytes.len() as u64));
        g.bench_function(name, |b| {
            b.iter(|| black_box(PolicyFile::from_bytes(&bytes, &path).unwrap()));
        });
        g.bench_function(format!("{name}_load"), |b| {
            b.iter(|| black_box(PolicyFile::load(&path).unwrap()));
        });
        g.bench_function(format!("{name}_load_whole"), |b| {
            b.iter(|| {
                let bytes = std::fs::read(&path).unwrap();
                black_box(PolicyFile::from_bytes(&bytes, &path).unwrap())
            });
        });
    }
    let _ = std::fs::remove_file(&path);
    g.finish();
}

criterion_group!(benches, bench_files);
criterion_main!(benches);
