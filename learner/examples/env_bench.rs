//! Benchmark of the RL environment (docs/performance.md): policy steps per
//! second of `VecEnv` (50 control cycles of hw-sim and rt-controller's
//! cycle at 1 kHz per step), observed from ground truth or through the
//! frozen representation (an untrained Full Model: the cost of encoding
//! does not depend on the weights), with Gaussian actions of σ 0.5. One
//! JSON line per run; episodes are reset as they end, as in training.
//!
//! Usage: `env_bench ground-truth|representation|representation-burn
//! NUM_ENVS THREADS STEPS` (THREADS 0: all cores, for the environments and
//! the encoder's CPU path alike; STEPS are batch steps, each NUM_ENVS policy
//! steps). `representation` encodes through the inference API's CPU path,
//! `representation-burn` through burn's `encode` (its threads:
//! RAYON_NUM_THREADS).
//!
//! `env_bench --quick`: a few batch steps of 2 environments on one thread,
//! from ground truth and through the representation's CPU path, which runs
//! in seconds in a debug build (scripts/test.sh): that the benchmark still
//! runs, not a measurement.

use learner::models::{Encoder, ModelConfig, Normaliser, ReprNet, init};
use learner::rl::observe::{GroundTruth, Observer};
use learner::rl::{BatchEnv, Representation, RlEnvConfig, VecEnv};
use std::sync::Arc;
use std::time::Instant;

fn main() {
    let usage = "usage: env_bench ground-truth|representation|representation-burn NUM_ENVS \
                 THREADS STEPS, or env_bench --quick";
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("--quick") {
        bench("ground-truth", 2, 1, 20);
        bench("representation", 2, 1, 2);
        return;
    }
    let what = args.get(1).expect(usage).as_str();
    let n: usize = args.get(2).expect(usage).parse().expect(usage);
    let threads: usize = args.get(3).expect(usage).parse().expect(usage);
    let steps: usize = args.get(4).expect(usage).parse().expect(usage);
    bench(what, n, threads, steps);
}

/// One run: `steps` batch steps of `n` environments observed by `what`,
/// printed as a JSON line.
fn bench(what: &str, n: usize, threads: usize, steps: usize) {
    let usage = "env_bench: the observation is ground-truth, representation or representation-burn";
    let observer: Arc<dyn Observer> = match what {
        "ground-truth" => Arc::new(GroundTruth),
        "representation" | "representation-burn" => {
            let cfg = ModelConfig::default();
            let dev = burn::prelude::Device::flex();
            let net = init::seeded(ReprNet::new(&cfg, &dev), 0);
            let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
            let encoder = Encoder::new(net, cfg, Normaliser::identity(), &dev)
                .with_fast_path(what == "representation")
                .with_threads(if threads == 0 { cores } else { threads });
            Arc::new(Representation::new(Box::new(encoder)))
        }
        _ => panic!("{usage}"),
    };
    let cfg = RlEnvConfig::default();
    let mut env = VecEnv::new(&cfg, n, observer.clone(), threads).expect("environment");
    let mut rng = stack_common::rng::seeded(1, 0);
    let mut seed = 0u64;
    let which: Vec<_> = (0..n)
        .map(|i| {
            seed += 1;
            (i, seed)
        })
        .collect();
    env.reset(&which).expect("reset");
    let mut actions = vec![0.0; 4 * n];
    let started = Instant::now();
    let mut episodes = 0usize;
    for _ in 0..steps {
        for a in &mut actions {
            *a = 0.5 * stack_common::rng::normal(&mut rng);
        }
        let done: Vec<usize> = env
            .step(&actions)
            .expect("step")
            .iter()
            .enumerate()
            .filter(|(_, o)| o.done())
            .map(|(i, _)| i)
            .collect();
        if !done.is_empty() {
            episodes += done.len();
            let which: Vec<_> = done
                .into_iter()
                .map(|i| {
                    seed += 1;
                    (i, seed)
                })
                .collect();
            env.reset(&which).expect("reset");
        }
    }
    let secs = started.elapsed().as_secs_f64();
    // The encoder's share: the same batch of views observed again, alone.
    let views: Vec<_> = (0..n).filter_map(|i| env.env(i).view()).collect();
    let mut out = vec![0.0; n * observer.dim()];
    let t = Instant::now();
    let reps = 5;
    for _ in 0..reps {
        observer.observe(&views, &mut out);
    }
    let observe_s = t.elapsed().as_secs_f64() / reps as f64;
    println!(
        "{{\"observation\":\"{what}\",\"num_envs\":{n},\"threads\":{},\"batch_steps\":{steps},\"episodes_ended\":{episodes},\"seconds\":{secs:.3},\"env_steps_per_s\":{:.2},\"observe_batch_ms\":{:.3}}}",
        env.threads(),
        (steps * n) as f64 / secs,
        1e3 * observe_s
    );
}
