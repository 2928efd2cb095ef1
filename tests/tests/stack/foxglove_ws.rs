//! `learner stack --foxglove-ws`: a Foxglove WebSocket client
//! (tests/data/foxglove_ws_client.py, Python `websockets`) on loopback
//! receives every channel of the running stack and decodes each message
//! with the channel's advertised schema (CDR by mcap-ros2-support, JSON by
//! jsonschema); misbehaving clients get an answer and lose only their own
//! session, and the episodes go on.

use learner_node::stack::Managed;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// Every channel a log with the Foxglove views has.
const TOPICS: [&str; 14] = [
    "/camera/calibration",
    "/camera/depth",
    "/camera/rgb",
    "/camera/rgbd",
    "/config",
    "/controller/sensor",
    "/controller/status",
    "/ee/pose",
    "/events",
    "/ft/wrench",
    "/policy/action",
    "/scene",
    "/sim/episode",
    "/tf",
];

/// The `ws://` address the node printed into `log`, waiting up to `timeout`
/// for the stack to start.
fn served_at(log: &Path, stack: &mut Managed, timeout: Duration) -> String {
    let start = Instant::now();
    loop {
        let text = std::fs::read_to_string(log).unwrap_or_default();
        if let Some(at) = text.find("ws://") {
            let url: String = text[at..]
                .chars()
                .take_while(|c| !c.is_whitespace())
                .collect();
            return url;
        }
        assert!(
            stack.try_wait().is_none(),
            "the stack ended before serving:\n{text}"
        );
        assert!(
            start.elapsed() < timeout,
            "no ws:// address after {timeout:?}:\n{text}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

#[test]
fn a_foxglove_websocket_client_decodes_every_channel_of_the_running_stack() {
    let Some(py) = test_support::venv::INTEROP.python(
        "websockets, mcap_ros2.decoder, jsonschema",
        "websockets, mcap-ros2-support and jsonschema are",
    ) else {
        return;
    };
    let _g = tests::exclusive();
    let bins = tests::stack_bins();
    let dir = test_support::scratch_dir("stack-foxglove-ws");
    // Lockstep: the episodes run at the machine's pace, whatever its load,
    // until the test stops them (the client needs two episode starts).
    let mut cmd = Command::new(bins.join("learner"));
    cmd.args(["stack", "--lockstep", "--episodes", "1000"])
        .args(["--foxglove-ws", "0", "--namespace"])
        .arg(tests::unique_namespace("foxglove-ws"))
        .arg("--log-dir")
        .arg(dir.join("logs"));
    let log = dir.join("stack.log");
    let mut stack = Managed::spawn("stack", cmd, Some(&log)).unwrap();
    let url = served_at(&log, &mut stack, Duration::from_secs(180));
    assert!(url.starts_with("ws://127.0.0.1:"), "loopback: {url}");
    let required = TOPICS.join(",");
    let client = Command::new(&py)
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("data/foxglove_ws_client.py"))
        .args([url.as_str(), required.as_str(), "240"])
        .output()
        .unwrap();
    stack.stop(Duration::from_secs(10));
    let stack_out = std::fs::read_to_string(&log).unwrap_or_default();
    assert!(
        client.status.success(),
        "{}\nstack:\n{stack_out}",
        String::from_utf8_lossy(&client.stderr)
    );
    let s: serde_json::Value = serde_json::from_slice(&client.stdout).unwrap();
    assert_eq!(s["errors"], serde_json::json!([]), "{s}");
    assert_eq!(s["refused_status"], 400, "{s}");
    assert_eq!(s["subprotocol"], "foxglove.websocket.v1");
    assert_eq!(s["server_op"], "serverInfo");
    assert_eq!(s["topics"], serde_json::json!(TOPICS), "{s}");
    // Every channel delivered (at least twice: the latched ones on
    // subscribing and again at the next episode's start) and decoded.
    for t in TOPICS {
        let n = s["counts"][t].as_u64().unwrap_or(0);
        assert!(n >= 2, "{t}: {n} messages\n{s}");
    }
    // A viewer joining mid-episode got the episode's configuration and its
    // scene with the arm before any live sensor frame: kept for it, not
    // waited for until the next episode.
    assert_eq!(s["late_first_topics"][0], "/config", "{s}");
    assert_eq!(s["late_arm"], true, "{s}");
    assert!(
        s["late_first_topics"]
            .as_array()
            .unwrap()
            .iter()
            .any(|t| t == "/events"),
        "{s}"
    );
    let statuses: Vec<&str> = s["statuses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v["message"].as_str().unwrap())
        .collect();
    for expected in [
        "not JSON",
        "no channel 4242",
        "\"getParameters\": not supported",
        "subscription id 0 is in use",
        "no subscription 7777",
    ] {
        assert!(
            statuses.iter().any(|m| m.contains(expected)),
            "{expected}: {statuses:?}"
        );
    }
    // Unsubscribing stops that channel and only that one.
    assert_eq!(s["sensor_after_unsubscribe"], 0, "{s}");
    assert!(s["others_after_unsubscribe"].as_u64().unwrap() > 0, "{s}");
    // An oversized request: closed with 1009, the server and its other
    // sessions unaffected (the episodes went on).
    assert_eq!(s["oversized_close"], 1009, "{s}");
    assert!(stack_out.contains("Message too long"), "{stack_out}");
    assert!(stack_out.contains(": completed after"), "{stack_out}");
}
