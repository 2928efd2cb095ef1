//! The scripted heuristic completes the insertion on all four pegs in the
//! fast path (simulator + control core in one process), from randomised box
//! poses.

use hw_sim::{PegShape, Stage, WorldConfig};
use learner::fast_env::FastEnv;
use learner_node::policy::{HeuristicConfig, HeuristicPolicy, TaskGeometry};
use rt_controller::ControllerConfig;

fn episode(peg: PegShape, seed: u64) -> (Stage, f64) {
    let mut world = WorldConfig::default();
    world.task.peg = peg;
    let mut env = FastEnv::new(world, ControllerConfig::default()).unwrap();
    env.reset(seed).unwrap();
    let task = TaskGeometry {
        hole_pose: env.world().hole_pose().unwrap(),
        symmetry: peg.symmetry_order(),
        depth_m: env.world().config().task.hole_depth_m,
    };
    let mut policy = HeuristicPolicy::new(HeuristicConfig::default());
    let mut obs = env.step(None).unwrap();
    // A collection episode's length (5 s): the policy must neither fault the
    // controller on its way (an impact on the box) nor at the bottom.
    for _ in 0..100 {
        let a = policy.act(&obs, &env.wrench, &task);
        obs = env.step(Some(&a)).unwrap();
        if std::env::var_os("HEURISTIC_TRACE").is_some() {
            let t = env.world().task().unwrap();
            println!(
                "{:.2} {:?} s=({:.4},{:.4},{:.4}) psi={:.3} contact={} a=({:.4},{:.4},{:.4},{:.3}) f={:.1}",
                env.world().time_s(),
                policy.phase(),
                t.s_m.x,
                t.s_m.y,
                t.s_m.z,
                t.s_psi_rad,
                t.in_contact,
                a[0],
                a[1],
                a[2],
                a[3],
                env.wrench.mean_force(8).norm()
            );
        }
    }
    let faults = env.controller_data().supervisor.counters.faults;
    assert_eq!(
        faults,
        0,
        "{} peg: the controller faulted ({:?})",
        peg.name(),
        env.controller_data().supervisor.fault()
    );
    (env.world().task().unwrap().best_stage, env.world().time_s())
}

#[test]
fn heuristic_completes_all_four_pegs() {
    // Two box poses per peg.
    for k in 0..2u64 {
        for (i, peg) in PegShape::ALL.into_iter().enumerate() {
            let seed = 11 + i as u64 + 4 * k;
            let (stage, t) = episode(peg, seed);
            println!(
                "{} (seed {seed}): {} after {t:.2} s",
                peg.name(),
                stage.name()
            );
            assert_eq!(
                stage,
                Stage::Completed,
                "{} peg, seed {seed}: {}",
                peg.name(),
                stage.name()
            );
        }
    }
}

#[test]
fn collection_mix_heuristic_runs_whole_episodes_without_a_fault() {
    use learner::collect::task_of;
    use learner_node::mix::{EpisodePolicy, Mix, MixedPolicy};
    // The collection's heuristic: 1 mm of noise on every position step.
    // It used to end most 5 s episodes in a force overload: impacts on the
    // box's top and the bottom, and noise winding the target into the
    // bottom while resting (54 of 59 heuristic episodes of a 10k-state
    // collection).
    let mix = Mix {
        heuristic_fraction: 1.0,
        end_after_completion: None,
        ..Mix::default()
    };
    let mut faults = Vec::new();
    for (i, peg) in PegShape::ALL.into_iter().enumerate() {
        for k in 0..2u64 {
            let seed = 1 + i as u64 + 4 * k;
            let mut world = WorldConfig::default();
            world.task.peg = peg;
            let mut env = FastEnv::new(world, ControllerConfig::default()).unwrap();
            env.reset(seed).unwrap();
            let task = task_of(env.world()).unwrap();
            let mut policy = MixedPolicy::new(&mix, seed);
            assert_eq!(policy.kind(), EpisodePolicy::Heuristic);
            let mut obs = env.step(None).unwrap();
            for _ in 0..100 {
                let a = policy.act(&obs, &env.wrench, &task);
                obs = env.step(Some(&a)).unwrap();
            }
            if let Some(f) = env.controller_data().supervisor.fault() {
                faults.push(format!("{} seed {seed}: {f:?}", peg.name()));
            }
        }
    }
    assert!(faults.is_empty(), "{faults:#?}");
}
