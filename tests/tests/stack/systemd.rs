//! systemd notifications, and SIGTERM: the hold, then a clean exit.

use shared_mem_schema::transport;
use shared_mem_schema::{ControllerMode, SensorFrame};
use std::process::Command;
use std::time::{Duration, Instant};
use tests::wait_for;

#[test]
fn systemd_notifications_and_sigterm_hold_then_clean_exit() {
    use std::os::unix::net::UnixDatagram;
    let _g = tests::exclusive();
    let ns = tests::unique_namespace("systemd");
    let dir = test_support::scratch_dir("systemd");
    let sock_path = dir.join("notify.sock");
    let sock = UnixDatagram::bind(&sock_path).unwrap();
    sock.set_read_timeout(Some(Duration::from_millis(200)))
        .unwrap();
    let _sim = tests::start("hw-sim", &["--namespace", &ns, "--no-camera"], &dir);
    let mut cmd = Command::new(tests::stack_bins().join("rt-controller"));
    cmd.args(["--namespace", &ns, "--no-realtime"])
        .env("NOTIFY_SOCKET", &sock_path)
        .env("WATCHDOG_USEC", "1000000");
    let mut ctl = learner_node::stack::Managed::spawn(
        "rt-controller",
        cmd,
        Some(&dir.join("rt-controller.log")),
    )
    .unwrap();
    let node = transport::create_node("e2e-systemd").unwrap();
    let frames = transport::subscriber::<SensorFrame>(&node, &ns).unwrap();
    let mut got = Vec::new();
    let mut buf = [0u8; 256];
    let start = Instant::now();
    while start.elapsed() < Duration::from_secs(20)
        && !(got.iter().any(|m: &String| m.contains("READY=1"))
            && got.iter().any(|m| m == "WATCHDOG=1"))
    {
        if let Ok(n) = sock.recv(&mut buf) {
            got.push(String::from_utf8_lossy(&buf[..n]).into_owned());
        }
    }
    assert!(
        got.iter().any(|m| m.contains("READY=1")),
        "no READY: {got:?}"
    );
    assert!(
        got.iter().any(|m| m == "WATCHDOG=1"),
        "no WATCHDOG: {got:?}"
    );
    assert!(wait_for(&frames, Duration::from_secs(5), |_| true).is_some());
    ctl.signal(libc::SIGTERM);
    let held = wait_for(&frames, Duration::from_secs(2), |f| {
        f.mode == ControllerMode::Holding as u32
    });
    assert!(
        held.is_some(),
        "SIGTERM did not bring the controller to a hold"
    );
    let status = ctl.wait_timeout(Duration::from_secs(5)).expect("exits");
    assert!(status.success(), "exit status {status}");
    let mut stopping = false;
    while let Ok(n) = sock.recv(&mut buf) {
        stopping |= String::from_utf8_lossy(&buf[..n]).contains("STOPPING=1");
    }
    assert!(stopping, "no STOPPING notification");
}
