//! Diagnosis of RL episodes: how episodes end (fault codes, the step of
//! termination), how close the tip gets to the hole, and the outcome, for a
//! trained checkpoint's policy (mean, or sampled with its own σ; observing
//! what it was trained on, the ground truth or a representation's z means)
//! or a scripted proportional policy. One line per episode and a summary;
//! `RL_PROBE_PATH=N` also prints where the tip is every N steps.
//!
//! Usage: `rl_probe CHECKPOINT|scripted|heuristic|impactMM EPISODES [sample]`
//! (`scripted`: centre over the hole, then descend; `heuristic`: the data
//! collection's heuristic policy). Episodes use seeds from 1 000 000, as
//! `learner policy eval` does. `impactMM`: come down onto the box's top
//! face 12 mm beside the hole at a constant step of MM mm per policy step.

use learner::rl::observe::{GroundTruth, ObservationKind, Observer};
use learner::rl::run::read_checkpoint;
use learner::rl::{Outcome, RlEnv, RlEnvConfig};

fn main() {
    let usage = "usage: rl_probe CHECKPOINT|scripted|heuristic|impactMM EPISODES [sample]";
    let args: Vec<String> = std::env::args().collect();
    let what = args.get(1).expect(usage).clone();
    let episodes: u64 = args.get(2).expect(usage).parse().expect(usage);
    let sample = args.get(3).is_some_and(|a| a == "sample");
    let impact_mm: Option<f64> = what.strip_prefix("impact").map(|v| v.parse().expect(usage));
    let mut observation = ObservationKind::GroundTruth;
    let (cfg, policy) = if what == "scripted" || what == "heuristic" || impact_mm.is_some() {
        // Scripted steps up to the controller's 1 cm clamp.
        let mut cfg = RlEnvConfig::default();
        cfg.action.max_step_m = 0.01;
        (cfg, None)
    } else {
        let c = read_checkpoint(std::path::Path::new(&what)).expect("checkpoint");
        let p = c
            .chosen_policy(std::env::var_os("RL_PROBE_LAST").is_some())
            .policy
            .clone();
        observation = c.config.observation.clone();
        (c.config.env.clone(), Some(p))
    };
    // What the policy observes: the ground truth or the representation's z
    // means (the latter needs the camera rendered every step).
    let observer = observation.observer().expect("observer");
    if let Some(p) = &policy {
        assert_eq!(
            p.mlp().input(),
            observer.dim(),
            "the checkpoint's policy takes {} inputs; its observation {:?} gives {}",
            p.mlp().input(),
            observation,
            observer.dim()
        );
    }
    let camera = observer.needs_camera();
    let path_every: Option<u32> = std::env::var("RL_PROBE_PATH")
        .ok()
        .map(|v| v.parse().expect("RL_PROBE_PATH: steps"));
    let mut env = RlEnv::new(&cfg).expect("env");
    learner::rl::observe::check_camera(&cfg.world.camera, observer.as_ref())
        .unwrap_or_else(|e| panic!("{e}"));
    let mut heuristic = learner_node::policy::HeuristicPolicy::new(Default::default());
    let mut rng = stack_common::rng::seeded(7, 0);
    let mut counts = [0u32; 4];
    let mut terminated = 0;
    for ep in 0..episodes {
        env.reset(1_000_000 + ep, camera).expect("reset");
        heuristic.reset();
        let mut min_xy = f64::MAX;
        let mut min_z = f64::MAX;
        let mut fault = 0;
        let mut max_force: f64 = 0.0;
        let (end, o) = loop {
            let mut obs = [0.0; learner::rl::observe::GROUND_TRUTH_DIM];
            GroundTruth.observe(&[env.view().unwrap()], &mut obs);
            let mut seen = vec![0.0; observer.dim()];
            observer.observe(&[env.view().unwrap()], &mut seen);
            let a: Vec<f64> = match &policy {
                Some(p) if sample => p.sample(&seen, &mut rng),
                Some(p) => p.means(&seen),
                None if what == "heuristic" => {
                    let d = heuristic.act(
                        env.observation().unwrap(),
                        &env.fast().wrench,
                        &env.task_geometry(),
                    );
                    env.action_scale().from_delta(&d).to_vec()
                }
                None if impact_mm.is_some() => {
                    // Centre 12 mm beside the hole's axis (on the top face),
                    // then come down at a constant step onto the face.
                    let task = env.task_geometry();
                    let s = nalgebra::Vector3::new(obs[0], obs[1], obs[2]) * 0.1;
                    let goal = nalgebra::Vector3::new(0.012, 0.0, 0.0);
                    let mut d = goal - s;
                    let step = impact_mm.unwrap() * 1e-3;
                    d.z = if (d.x * d.x + d.y * d.y).sqrt() > 0.001 && s.z > 0.02 {
                        0.0
                    } else {
                        -step
                    };
                    let d = task.hole_pose.rotation * d;
                    env.action_scale()
                        .from_delta(&[d.x, d.y, d.z, 0.0])
                        .to_vec()
                }
                None => {
                    // s in the hole frame, 0.1 m units; act in the hole frame
                    // rotated to the base frame.
                    let task = env.task_geometry();
                    let s = nalgebra::Vector3::new(obs[0], obs[1], obs[2]) * 0.1;
                    let xy = (s.x * s.x + s.y * s.y).sqrt();
                    let dz = if xy < 0.0005 {
                        -0.002
                    } else if s.z > 0.01 {
                        -0.003
                    } else {
                        0.0
                    };
                    let d = task.hole_pose.rotation * nalgebra::Vector3::new(-s.x, -s.y, dz);
                    let sc = env.action_scale().clone();
                    // obs[3] is s_ψ/(π/k); π/4 is the square's (k = 4) scale.
                    let roll = -obs[3] * std::f64::consts::PI / 4.0;
                    sc.from_delta(&[d.x, d.y, d.z, roll]).to_vec()
                }
            };
            let o = env.step(&a, camera).expect("step");
            let t = env.task();
            if path_every.is_some_and(|n| o.steps.is_multiple_of(n)) {
                println!(
                    "  step {:3} s ({:6.1}, {:6.1}, {:6.1}) mm psi {:6.3} reward {:.2} ({:?}) contact {} a {:?}",
                    o.steps,
                    t.s_m.x * 1e3,
                    t.s_m.y * 1e3,
                    t.s_m.z * 1e3,
                    t.s_psi_rad,
                    o.reward,
                    o.stage,
                    t.in_contact,
                    a.iter()
                        .map(|v| (v * 100.0).round() / 100.0)
                        .collect::<Vec<_>>()
                );
            }
            if std::env::var_os("RL_PROBE_TRACE").is_some() && t.s_m.z < 0.003 {
                let w = env.fast().sensor_frame().wrench;
                println!(
                    "  step {:3} s ({:5.2}, {:5.2}, {:5.2}) mm psi {:6.3} contact {} F ({:5.1}, {:5.1}, {:5.1}) a {:?}",
                    o.steps,
                    t.s_m.x * 1e3,
                    t.s_m.y * 1e3,
                    t.s_m.z * 1e3,
                    t.s_psi_rad,
                    t.in_contact,
                    w[0],
                    w[1],
                    w[2],
                    a.iter()
                        .map(|v| (v * 100.0).round() / 100.0)
                        .collect::<Vec<_>>()
                );
                // The peg's bottom corners in the hole frame: height and how
                // far inside the hole's outline (negative: over the rim).
                let w = env.fast().world();
                if let (Some(peg), Some(b), Some(hole)) = (w.peg(), w.box_geometry(), w.hole_pose())
                {
                    let to_hole = hole.inverse() * w.link_pose(peg.link) * peg.sensor_in_link;
                    let corners: Vec<String> = peg
                        .prism
                        .polygon
                        .iter()
                        .map(|c| {
                            let p = to_hole * nalgebra::Point3::new(c[0], c[1], peg.prism.z1);
                            format!(
                                "({:.2} z, {:.2} in)",
                                p.z * 1e3,
                                b.hole_inset([p.x, p.y]) * 1e3
                            )
                        })
                        .collect();
                    println!("     corners mm {}", corners.join(" "));
                }
            }
            min_xy = min_xy.min((t.s_m.x.powi(2) + t.s_m.y.powi(2)).sqrt());
            min_z = min_z.min(t.s_m.z);
            for w in env.fast().wrench.ordered() {
                max_force = max_force.max((w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt());
            }
            if o.done() {
                if o.terminated {
                    terminated += 1;
                    fault = env.fast().sensor_frame().fault_code;
                }
                break (o.steps, o);
            }
        };
        let mut seen = vec![0.0; observer.dim()];
        observer.observe(&[env.view().unwrap()], &mut seen);
        let mean = policy.as_ref().map(|p| p.means(&seen)).unwrap_or_default();
        let hole_z = env.task_geometry().hole_pose.rotation * nalgebra::Vector3::z();
        let peg_z = env.observation().unwrap().ee_rot * nalgebra::Vector3::z();
        println!(
            "   tilt {:.4} rad, mean action {:?}",
            hole_z.angle(&peg_z).min(hole_z.angle(&-peg_z)),
            mean.iter()
                .map(|v| (v * 1000.0).round() / 1000.0)
                .collect::<Vec<_>>()
        );
        // Where the tip ended and where the hole was, base frame: a policy
        // that does not see the box goes to the same place every episode.
        let hole = env.task_geometry().hole_pose.translation.vector;
        let tip = env.observation().unwrap().ee_pos;
        println!(
            "   base frame: tip ({:.1}, {:.1}) mm, hole ({:.1}, {:.1}) mm",
            tip.x * 1e3,
            tip.y * 1e3,
            hole.x * 1e3,
            hole.y * 1e3
        );
        counts[o.outcome.index()] += 1;
        println!(
            "ep {ep}: {:?} steps {end} fault {fault} min_xy {:.1} mm min_z {:.1} mm max|F| {:.0} N norm {:.3} final s ({:.1}, {:.1}, {:.1}) mm psi {:.3}",
            o.outcome,
            min_xy * 1e3,
            min_z * 1e3,
            max_force,
            learner::rl::reward::normalised_return(o.episode_reward, cfg.max_steps),
            env.task().s_m.x * 1e3,
            env.task().s_m.y * 1e3,
            env.task().s_m.z * 1e3,
            env.task().s_psi_rad,
        );
    }
    println!(
        "outcomes {:?} over {episodes}; terminated {terminated}",
        Outcome::ALL
            .iter()
            .zip(counts)
            .map(|(o, c)| format!("{}: {c}", o.name()))
            .collect::<Vec<_>>()
    );
}
