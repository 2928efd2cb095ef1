//! Episodes: configuration errors, refused commands, seeds, determinism and
//! perturbations.

use hw_sim::{SimError, World, WorldConfig};

fn hold_torques(world: &World) -> Vec<f64> {
    // Gravity compensation from the model plus joint damping: enough to
    // keep the arm near its pose without a controller.
    let model = world.model();
    let mut data = model.create_data();
    let g = robot_model::gravity(model, &mut data, world.q()).clone();
    g.iter().zip(world.v()).map(|(g, v)| g - 5.0 * v).collect()
}

#[test]
fn bad_configuration_names_the_field() {
    let err = WorldConfig::from_toml("dt_s = 0.001\n[task]\nclearance_mm = 2\n").unwrap_err();
    assert!(err.to_string().contains("clearance_mm"), "{err}");
    let mut c = WorldConfig::default();
    c.task.hole_depth_m = 0.2;
    let err = World::new(c).err().expect("refused");
    assert!(err.to_string().contains("task.hole_depth_m"), "{err}");
    let c = WorldConfig {
        robot: "/nonexistent/robot.urdf".into(),
        ..Default::default()
    };
    let err = World::new(c).err().expect("refused");
    assert!(err.to_string().contains("/nonexistent/robot.urdf"), "{err}");
    let parsed = WorldConfig::from_toml("seed = 9\n[task]\npeg = \"hexagon\"\n").unwrap();
    assert_eq!(parsed.task.peg, hw_sim::PegShape::Hexagon);
    assert_eq!(parsed.seed, 9);
}

#[test]
fn a_nan_torque_is_refused_and_changes_nothing() {
    let mut world = World::new(WorldConfig::default()).unwrap();
    let tau = hold_torques(&world);
    world.step(&tau).unwrap();
    let q = world.q().to_vec();
    let mut bad = tau.clone();
    bad[3] = f64::NAN;
    match world.step(&bad) {
        Err(SimError::NonFiniteTorque { joint: 3, .. }) => {}
        other => panic!("expected a refusal, got {other:?}"),
    }
    assert!(matches!(
        world.step(&tau[..6]),
        Err(SimError::TorqueLength {
            got: 6,
            expected: 7
        })
    ));
    assert_eq!(world.q(), &q[..]);
    assert_eq!(world.step_index(), 1);
}

fn run(config: &WorldConfig, steps: usize) -> (Vec<f64>, Vec<[f64; 6]>) {
    let mut world = World::new(config.clone()).unwrap();
    let mut qs = Vec::new();
    let mut ws = Vec::new();
    for _ in 0..steps {
        let tau = hold_torques(&world);
        world.step(&tau).unwrap();
        qs.extend_from_slice(&world.readings().q);
        ws.push(world.readings().wrench);
    }
    (qs, ws)
}

#[test]
fn same_seed_same_run_bit_for_bit() {
    let mut c = WorldConfig::default();
    c.noise.q_std_rad = 1e-4;
    c.noise.force_std_n = 0.1;
    c.perturbations.random_pushes = 2;
    c.perturbations.random_window_s = [0.0, 0.3];
    c.seed = 42;
    let a = run(&c, 400);
    let b = run(&c, 400);
    assert!(
        a.0.iter()
            .zip(&b.0)
            .all(|(x, y)| x.to_bits() == y.to_bits())
    );
    assert!(
        a.1.iter()
            .zip(&b.1)
            .all(|(x, y)| x.iter().zip(y).all(|(p, q)| p.to_bits() == q.to_bits()))
    );
    c.seed = 43;
    let d = run(&c, 400);
    assert_ne!(a.0, d.0, "a different seed must give a different run");
}

/// Each sensor channel draws from its own stream: turning force noise on
/// leaves the joint-position noise as it was, and a channel without noise
/// reads the plain value.
#[test]
fn noise_channels_do_not_shift_each_other() {
    let mut c = WorldConfig::default();
    c.noise.q_std_rad = 1e-4;
    c.seed = 7;
    let quiet = run(&c, 200);
    c.noise.force_std_n = 0.5;
    let noisy = run(&c, 200);
    assert_eq!(quiet.0, noisy.0, "force noise moved the joint readings");
    assert_ne!(quiet.1, noisy.1, "force noise had no effect");
    c.noise.q_std_rad = 0.0;
    let mut world = World::new(c).unwrap();
    world.step(&hold_torques(&world)).unwrap();
    assert_eq!(
        world.readings().q,
        world.q(),
        "no q noise, yet q was perturbed"
    );
}

/// `noise.episode_scale` draws one factor per episode within its range and
/// multiplies the deviations by it: the readings' spread about the truth
/// follows the factor, and a fixed scale adds no draw of its own.
#[test]
fn the_noise_scale_is_drawn_per_episode_and_scales_the_deviations() {
    let mut c = WorldConfig::default();
    c.noise.q_std_rad = 1e-3;
    c.seed = 11;
    let plain = run(&c, 50);
    // A fixed scale multiplies and draws nothing more: half of twice the
    // deviation is the same run (halving and doubling are exact).
    let mut halved = c.clone();
    halved.noise.q_std_rad = 2e-3;
    halved.noise.episode_scale = [0.5, 0.5];
    assert_eq!(plain, run(&halved, 50), "a fixed scale changed the draws");

    c.noise.episode_scale = [0.0, 2.0];
    let mut world = World::new(c.clone()).unwrap();
    let mut scales = Vec::new();
    for seed in 0..40 {
        world.reset(seed).unwrap();
        let k = world.noise_scale();
        assert!((0.0..2.0).contains(&k), "seed {seed}: scale {k}");
        // The spread of q's readings about the truth over some steps.
        let mut sq = 0.0;
        let n = 30;
        for _ in 0..n {
            world.step(&hold_torques(&world)).unwrap();
            let (r, q) = (&world.readings().q, world.q());
            sq += r.iter().zip(q).map(|(a, b)| (a - b).powi(2)).sum::<f64>();
        }
        let rms = (sq / (n * world.q().len()) as f64).sqrt();
        // 210 draws: the sample RMS lies within 20 % of its deviation.
        assert!(
            (rms - k * 1e-3).abs() <= 0.2 * k * 1e-3 + 1e-12,
            "seed {seed}: scale {k}, RMS {rms}"
        );
        scales.push(k);
    }
    let (lo, hi) = scales
        .iter()
        .fold((f64::MAX, f64::MIN), |(l, h), &k| (l.min(k), h.max(k)));
    assert!(
        lo < 0.5 && hi > 1.5,
        "scales not spread over the range: {lo}..{hi}"
    );

    c.noise.episode_scale = [1.0, 0.5];
    let Err(err) = World::new(c) else {
        panic!("a range [1, 0.5] was accepted");
    };
    assert!(err.to_string().contains("noise.episode_scale"), "{err}");
}

#[test]
fn seeds_place_the_box_within_its_region() {
    let mut c = WorldConfig::default();
    // Not symmetric under a half turn: a box yawed about 0 would start it
    // 180° out of line.
    c.task.peg = hw_sim::PegShape::Semicircle;
    let mut world = World::new(c.clone()).unwrap();
    let tip = world.peg_tip_pose().translation.vector;
    let mut seen = Vec::new();
    for seed in 0..20 {
        world.reset(seed).unwrap();
        let h = world.hole_pose().unwrap();
        let p = h.translation.vector;
        assert!((p.x - tip.x).abs() <= c.task.box_xy_range_m[0] + 1e-12);
        assert!((p.y - tip.y).abs() <= c.task.box_xy_range_m[1] + 1e-12);
        assert!((p.z - c.task.box_height_m).abs() < 1e-12);
        // The yaw is drawn about the one that fits the peg as the arm
        // starts: the peg starts within the range of alignment.
        let psi = world.task().unwrap().s_psi_rad;
        assert!(psi.abs() <= c.task.box_yaw_range_rad + 1e-9, "{psi}");
        seen.push(p.x);
    }
    seen.sort_by(f64::total_cmp);
    seen.dedup();
    assert_eq!(seen.len(), 20, "placements repeat across seeds");
}

#[test]
fn a_push_moves_the_arm_and_only_while_it_lasts() {
    let base = WorldConfig::default();
    let mut pushed = base.clone();
    pushed.perturbations.pushes.push(hw_sim::config::Push {
        start_s: 0.1,
        duration_s: 0.05,
        link: 7,
        force_n: [0.0, 30.0, 0.0],
    });
    let (qa, _) = run(&base, 90);
    let (qb, _) = run(&pushed, 90);
    // Identical until the push starts (step 100 would be the first).
    assert_eq!(qa, qb);
    let (qa, _) = run(&base, 300);
    let (qb, _) = run(&pushed, 300);
    let dev: f64 = qa
        .iter()
        .zip(&qb)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(dev > 1e-3, "a 30 N push left the arm where it was ({dev})");
}
