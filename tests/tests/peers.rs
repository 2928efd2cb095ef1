//! What another process on the machine can and cannot do to the stack over
//! shared memory: a reset command cannot make hw-sim read a file outside
//! its robots nor turn its torque clamp off, and nobody can publish beside
//! the hardware.

use shared_mem_schema::process::mono_now_ns;
use shared_mem_schema::transport::{self, TransportError};
use shared_mem_schema::{EpisodeReport, HardwareState, Header, SimCommand};
use std::time::{Duration, Instant};

/// Sends a reset with `world` (TOML) and returns hw-sim's answer.
fn reset(
    commands: &transport::Pub<SimCommand>,
    reports: &transport::Sub<EpisodeReport>,
    seq: u64,
    world: &str,
) -> EpisodeReport {
    let start = Instant::now();
    let mut sent_at = None::<Instant>;
    while start.elapsed() < Duration::from_secs(60) {
        // Sent again now and then: a simulator still starting misses it.
        if sent_at.is_none_or(|t| t.elapsed() > Duration::from_millis(500)) {
            transport::send_with(commands, |c| {
                c.header = Header::new(seq, mono_now_ns(), 0, 0);
                c.command = SimCommand::RESET;
                c.seed = 1;
                c.config_len = world.len() as u32;
                c.config_toml[..world.len()].copy_from_slice(world.as_bytes());
            })
            .unwrap();
            sent_at = Some(Instant::now());
        }
        let mut answer = None;
        transport::drain(reports, |r| {
            if r.command_seq == seq {
                answer = Some(*r);
            }
        })
        .unwrap();
        if let Some(r) = answer {
            return r;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    panic!("no answer from hw-sim to reset {seq}");
}

#[test]
fn peers_reach_no_file_relax_no_safety_setting_and_cannot_publish_for_the_hardware() {
    let _g = tests::exclusive();
    transport::quiet_logs();
    let ns = tests::unique_namespace("peers");
    let dir = test_support::scratch_dir("peers");
    let mut sim = tests::start("hw-sim", &["--namespace", &ns, "--no-camera"], dir.path());
    let node = transport::create_node("peer-test").unwrap();
    let commands = transport::publisher::<SimCommand>(&node, &ns).unwrap();
    let reports = transport::subscriber::<EpisodeReport>(&node, &ns).unwrap();

    // A robot path outside the built-in robots: refused unread.
    for (seq, robot) in [
        (1, "/etc/passwd"),
        (2, "/dev/zero"),
        (3, "../../etc/passwd"),
    ] {
        let r = reset(&commands, &reports, seq, &format!("robot = {robot:?}\n"));
        let text = r.message_text();
        assert_eq!(r.command_result, EpisodeReport::REJECTED, "{robot}: {text}");
        assert!(text.contains("no robot directory is configured"), "{text}");
        assert!(!text.contains("root:"), "file contents came back: {text}");
    }
    // A message may not relax the torque clamp.
    let r = reset(&commands, &reports, 4, "clamp_torques = false\n");
    assert_eq!(r.command_result, EpisodeReport::REJECTED);
    assert!(
        r.message_text().contains("clamp_torques"),
        "{}",
        r.message_text()
    );
    // Nor stall the simulator with an absurd solver.
    let r = reset(&commands, &reports, 5, "solver_iterations = 1000000000\n");
    assert_eq!(r.command_result, EpisodeReport::REJECTED);
    assert!(r.message_text().contains("solver_iterations"));
    // A built-in robot with the clamp on is fine.
    let r = reset(
        &commands,
        &reports,
        6,
        "robot = \"panda\"\nclamp_torques = true\n",
    );
    assert_eq!(r.command_result, EpisodeReport::OK, "{}", r.message_text());

    // The hardware's state has one publisher: hw-sim's.
    match transport::publisher::<HardwareState>(&node, &ns) {
        Err(TransportError::PublisherTaken { .. }) => {}
        Err(e) => panic!("wrong error: {e}"),
        Ok(_) => panic!("a second publisher of the hardware state was accepted"),
    }
    // A second hw-sim on the namespace stops at start with the reason.
    let second_dir = test_support::scratch_dir("peers-second");
    let mut second = tests::start(
        "hw-sim",
        &["--namespace", &ns, "--no-camera"],
        second_dir.path(),
    );
    let status = second
        .wait_timeout(Duration::from_secs(60))
        .expect("the second hw-sim must stop by itself");
    assert!(!status.success());
    let log = std::fs::read_to_string(second_dir.path().join("hw-sim.log")).unwrap();
    assert!(log.contains("already has its publisher"), "{log}");
    assert!(
        sim.try_wait().is_none(),
        "the first hw-sim must keep running"
    );
    sim.stop(Duration::from_secs(5));
}
