//! Garbage actions never produce torques beyond the limits.

use crate::{action, latest, start_sim_and_controller};
use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport;
use shared_mem_schema::{
    ControllerStatus, PolicyAction, SCHEMA_VERSION, SensorFrame, TorqueCommand,
};
use std::time::{Duration, Instant};
use test_support::{RngExt, Uniform};
use tests::wait_for;

#[test]
fn garbage_actions_never_produce_torques_beyond_limits() {
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("garbage");
    let dir = test_support::scratch_dir("garbage");
    // An action every two cycles, each to reach the control law: the rate
    // admission (an action at most every 25 steps, tested in
    // rt-controller-daemon's daemon_admission.rs) would queue and age most
    // of them. The speed bound still cuts valid steps (counted as accepted).
    let config = dir.join("every-cycle.toml");
    std::fs::write(&config, "[timing]\nmin_action_interval_steps = 1\n").unwrap();
    let (_sim, _ctl) = start_sim_and_controller(&ns, &dir, &["--config", config.to_str().unwrap()]);
    let model = robot_model::descriptions::builtin("iiwa14").unwrap();
    let limits = model.effort_limits();
    let cfg = rt_controller::ControllerConfig::default();
    let max_rate_step = cfg.qp.torque_rate_limit_nm_s * cfg.period_s;
    let node = transport::create_node("e2e-garbage").unwrap();
    let torques = transport::subscriber::<TorqueCommand>(&node, &ns).unwrap();
    let frames = transport::subscriber::<SensorFrame>(&node, &ns).unwrap();
    let status = transport::subscriber::<ControllerStatus>(&node, &ns).unwrap();
    let publisher = transport::publisher::<PolicyAction>(&node, &ns).unwrap();
    assert!(wait_for(&torques, Duration::from_secs(20), |_| true).is_some());
    let specials = [
        f64::NAN,
        f64::INFINITY,
        f64::NEG_INFINITY,
        -0.0,
        f64::MIN_POSITIVE / 4.0,
        -f64::MIN_POSITIVE / 3.0,
        1e300,
        -1e300,
        f64::MAX,
        0.5,
        -0.2,
    ];
    let mut rng = test_support::rng(7);
    let mut checked = 0usize;
    let mut bad = Vec::new();
    let mut rate_bad = Vec::new();
    let mut prev: Option<TorqueCommand> = None;
    let mut check = |c: &TorqueCommand| {
        for (i, &t) in c.tau[..7].iter().enumerate() {
            if !(t.is_finite() && t.abs() <= limits[i] + 1e-9) {
                bad.push((c.state_step, i, t));
            }
        }
        // Commands of consecutive steps of one episode: the rate limit.
        if let Some(p) = prev
            .filter(|p| p.header.episode == c.header.episode && p.state_step + 1 == c.state_step)
        {
            for i in 0..7 {
                let d = (c.tau[i] - p.tau[i]).abs();
                if d.is_nan() || d > max_rate_step + 1e-9 {
                    rate_bad.push((c.state_step, i, d));
                }
            }
        }
        prev = Some(*c);
        checked += 1;
    };
    const N: u64 = 4000;
    let (mut bad_schema, mut bad_value) = (0u64, 0u64);
    let mut newest = latest(&frames);
    for k in 0..N {
        let mut a = action(k + 1, 0.0, SCHEMA_VERSION, &newest);
        let pick = |rng: &mut test_support::Rng| match rng.random_range(0..3) {
            0 => specials[rng.random_range(0..specials.len())],
            1 => rng.uniform(-0.01, 0.01), // plausible steps
            _ => rng.uniform(-1e3, 1e3),   // far out of range
        };
        a.delta_pos_m = [pick(&mut rng), pick(&mut rng), pick(&mut rng)];
        a.delta_roll_rad = pick(&mut rng);
        if rng.random_range(0..50) == 0 {
            a.header.schema_version = SCHEMA_VERSION + rng.random_range(1..6);
            bad_schema += 1;
        } else if rt_controller::supervisor::Supervisor::check_action(&cfg.safety, &a.delta())
            .is_err()
        {
            bad_value += 1;
        }
        transport::send(&publisher, &a).unwrap();
        // One action in flight: wait for the second sensor frame published
        // after the send. Its cycle began after the first one's publication,
        // so it drained and applied this action; neither the daemon's
        // subscriber buffer nor its queue can overflow, however the
        // scheduler treats the processes.
        let sent = mono_now_ns();
        let mut after = 0;
        let deadline = Instant::now() + Duration::from_secs(10);
        while after < 2 {
            assert!(
                Instant::now() < deadline,
                "no sensor frames after action {k}"
            );
            transport::drain(&frames, |f| {
                after += (f.header.t_mono_ns > sent) as u32;
                newest = *f;
            })
            .unwrap();
            transport::drain(&torques, &mut check).unwrap();
            std::thread::sleep(Duration::from_micros(200));
        }
    }
    transport::drain(&torques, &mut check).unwrap();
    assert!(checked > 1000, "only {checked} torque commands seen");
    assert!(
        bad.is_empty(),
        "torques beyond limits: {:?}",
        &bad[..bad.len().min(5)]
    );
    assert!(
        rate_bad.is_empty(),
        "torque steps beyond the rate limit ({max_rate_step} N·m): {:?}",
        &rate_bad[..rate_bad.len().min(5)]
    );
    let s = wait_for(&status, Duration::from_secs(10), |s| {
        s.actions_received >= N
    })
    .expect("the status never counted the actions");
    assert_eq!(s.actions_received, N);
    // One action in flight: the queue never overflows, so every rejection
    // below is the validation's, not a flood's.
    assert_eq!(s.actions_overflow, 0, "{s:?}");
    // Every action received is accounted for exactly once. Each answers a
    // frame published a moment before: stale only if the machine stalled
    // for two policy periods (then counted as such).
    let stale =
        s.actions_too_old + s.actions_from_future + s.actions_other_episode + s.actions_replayed;
    assert_eq!(
        s.actions_accepted + s.actions_rejected + s.actions_ignored + s.actions_overflow + stale,
        N,
        "{s:?}"
    );
    assert_eq!(
        s.actions_from_future + s.actions_other_episode + s.actions_replayed,
        0,
        "{s:?}"
    );
    assert!(
        bad_schema > 0 && bad_value > N / 2,
        "{bad_schema} {bad_value}"
    );
    if s.faults == 0 {
        // Another schema is refused on arrival; a bad value only when not
        // dropped as stale before the control law sees it.
        assert!(s.actions_rejected <= bad_schema + bad_value, "{s:?}");
        assert!(
            s.actions_rejected + stale >= bad_schema + bad_value,
            "{s:?}"
        );
        assert_eq!(s.actions_ignored, 0);
    } else {
        // In Fault valid and invalid actions alike are ignored.
        assert!(s.actions_rejected >= bad_schema, "{s:?}");
        assert!(s.actions_rejected + s.actions_ignored >= bad_schema + bad_value);
    }
}
