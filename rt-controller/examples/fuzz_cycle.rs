//! The long fuzz run of the control cycle (the test suite runs a few
//! thousand cases of the same property, tests/fuzz_cycle.rs):
//!
//! ```sh
//! cargo run --release -p rt-controller --example fuzz_cycle -- 1000000 [seed]
//! ```
//!
//! Prints a progress line every 1% and, at the end, the count and the
//! result; a failing case is shrunk to a minimal one, printed, and the exit
//! status is 1. The seed (random unless given) is printed to replay a run.

#[path = "../tests/common/fuzz.rs"]
mod fuzz;

use proptest::strategy::Strategy;
use proptest::test_runner::{Config, RngAlgorithm, TestRng, TestRunner};
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let count: u64 = match args.next() {
        Some(a) => a.parse().unwrap_or_else(|_| usage(&a)),
        None => 1_000_000,
    };
    let seed: u64 = match args.next() {
        Some(a) => a.parse().unwrap_or_else(|_| usage(&a)),
        None => std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64),
    };
    println!("fuzz_cycle: {count} cases, seed {seed}");
    let mut seed_bytes = [0u8; 32];
    seed_bytes[..8].copy_from_slice(&seed.to_le_bytes());
    let config = Config {
        failure_persistence: None,
        ..Config::default()
    };
    let rng = TestRng::from_seed(RngAlgorithm::ChaCha, &seed_bytes);
    let mut runner = TestRunner::new_with_rng(config, rng);
    let strategy = fuzz::case();
    let step = (count / 100).max(1);
    let start = Instant::now();
    for i in 0..count {
        let tree = strategy
            .new_tree(&mut runner)
            .expect("the strategy has no filters");
        if let Err(e) = runner.run_one(tree, |case| fuzz::check(&case)) {
            println!("fuzz_cycle: case {} of {count} FAILED: {e}", i + 1);
            println!(
                "fuzz_cycle: {} cases run, result: FAILED (seed {seed})",
                i + 1
            );
            std::process::exit(1);
        }
        if (i + 1) % step == 0 {
            let s = start.elapsed().as_secs_f64();
            println!(
                "fuzz_cycle: {} / {count} cases ({:.0}%), {:.0} s, {:.0} cases/s",
                i + 1,
                100.0 * (i + 1) as f64 / count as f64,
                s,
                (i + 1) as f64 / s
            );
        }
    }
    println!(
        "fuzz_cycle: {count} cases run, result: ok ({:.1} s, seed {seed})",
        start.elapsed().as_secs_f64()
    );
}

fn usage(arg: &str) -> ! {
    eprintln!("fuzz_cycle: `{arg}` is not a number\nusage: fuzz_cycle [cases] [seed]");
    std::process::exit(2)
}
