//! The version handshake and a round trip through real iceoryx2 services.

use shared_mem_schema::transport::{self, Channel, TransportError};
use shared_mem_schema::{Header, Message, PolicyAction, SCHEMA_VERSION};

fn namespace(tag: &str) -> String {
    format!("test-{tag}-{}", std::process::id())
}

#[test]
fn peers_of_another_schema_version_are_refused_by_name() {
    transport::quiet_logs();
    let ns = namespace("version");
    let node = transport::create_node("schema-test-a").unwrap();
    let _ours = Channel::<PolicyAction>::open(&node, &ns).unwrap();
    let other = transport::create_node("schema-test-b").unwrap();
    let err = Channel::<PolicyAction>::open_as_version(&other, &ns, SCHEMA_VERSION + 41)
        .err()
        .expect("another version must be refused");
    match &err {
        TransportError::SchemaMismatch {
            ours,
            theirs,
            service,
            ..
        } => {
            assert_eq!(*ours, SCHEMA_VERSION + 41);
            assert_eq!(theirs, &SCHEMA_VERSION.to_string());
            assert!(service.ends_with("policy/action"));
        }
        e => panic!("wrong error: {e}"),
    }
    let text = err.to_string();
    assert!(text.contains("schema version"), "{text}");
}

#[test]
fn messages_round_trip_in_order() {
    transport::quiet_logs();
    let ns = namespace("roundtrip");
    let node = transport::create_node("schema-test-c").unwrap();
    let publisher = transport::publisher::<PolicyAction>(&node, &ns).unwrap();
    let subscriber = transport::subscriber::<PolicyAction>(&node, &ns).unwrap();
    for k in 1..=5u64 {
        let mut a = *PolicyAction::boxed_zeroed();
        a.header = Header::new(k, 0, 0, 1);
        a.delta_pos_m = [k as f64, 0.0, -0.0];
        transport::send(&publisher, &a).unwrap();
    }
    let mut seen = Vec::new();
    let n = transport::drain(&subscriber, |a| seen.push(a.header.seq)).unwrap();
    assert_eq!(n, 5);
    assert_eq!(seen, vec![1, 2, 3, 4, 5]);
    transport::send_with(&publisher, |a| a.header.seq = 9).unwrap();
    let mut last = 0;
    transport::drain(&subscriber, |a| last = a.header.seq).unwrap();
    assert_eq!(last, 9);
}

#[test]
fn a_topic_with_one_owner_refuses_a_second_publisher() {
    use shared_mem_schema::{HardwareState, TorqueCommand};
    transport::quiet_logs();
    let ns = namespace("owner");
    let owner = transport::create_node("schema-test-owner").unwrap();
    let _state = transport::publisher::<HardwareState>(&owner, &ns).unwrap();
    let _torque = transport::publisher::<TorqueCommand>(&owner, &ns).unwrap();
    let intruder = transport::create_node("schema-test-intruder").unwrap();
    for err in [
        transport::publisher::<HardwareState>(&intruder, &ns).err(),
        transport::publisher::<TorqueCommand>(&intruder, &ns).err(),
    ] {
        let err = err.expect("a second publisher must be refused");
        assert!(
            matches!(err, TransportError::PublisherTaken { .. }),
            "wrong error: {err}"
        );
        let text = err.to_string();
        assert!(text.contains("already has its publisher"), "{text}");
    }
    // Subscribers are not limited to one, and several processes may still
    // publish actions.
    let _sub = transport::subscriber::<HardwareState>(&intruder, &ns).unwrap();
    let _a = transport::publisher::<PolicyAction>(&owner, &ns).unwrap();
    let _b = transport::publisher::<PolicyAction>(&intruder, &ns).unwrap();
}
