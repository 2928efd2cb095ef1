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

#[test]
fn the_hardware_streams_take_only_their_reader_and_one_observer() {
    use shared_mem_schema::{HardwareState, SensorFrame, TorqueCommand};
    transport::quiet_logs();
    let ns = namespace("readers");
    let node = transport::create_rt_node("schema-test-readers").unwrap();
    let _torque_pub = transport::publisher::<TorqueCommand>(&node, &ns).unwrap();
    let hardware = transport::subscriber::<TorqueCommand>(&node, &ns).unwrap();
    let _observer = transport::subscriber::<TorqueCommand>(&node, &ns).unwrap();
    let _state_reader = transport::subscriber::<HardwareState>(&node, &ns).unwrap();
    let _state_observer = transport::subscriber::<HardwareState>(&node, &ns).unwrap();
    let intruder = transport::create_node("schema-test-reader-intruder").unwrap();
    for err in [
        transport::subscriber::<TorqueCommand>(&intruder, &ns).err(),
        transport::subscriber::<HardwareState>(&intruder, &ns).err(),
    ] {
        let err = err.expect("a third subscriber must be refused");
        assert!(
            matches!(err, TransportError::SubscribersTaken { max: 2, .. }),
            "wrong error: {err}"
        );
        assert!(err.to_string().contains("one observer"), "{err}");
    }
    // A reader that leaves frees its place.
    drop(hardware);
    transport::subscriber::<TorqueCommand>(&intruder, &ns).unwrap();
    // The sensor frames keep 8 readers (the learner, loggers, tools).
    let frames: Vec<_> = (0..8)
        .map(|_| transport::subscriber::<SensorFrame>(&intruder, &ns).unwrap())
        .collect();
    assert_eq!(frames.len(), 8);
}

#[test]
fn a_service_created_with_more_subscribers_is_refused() {
    use iceoryx2::prelude::*;
    use iceoryx2::service::attribute::{AttributeKey, AttributeSpecifier, AttributeValue};
    use shared_mem_schema::TorqueCommand;
    transport::quiet_logs();
    let ns = namespace("foreign-readers");
    let node = transport::create_node("schema-test-foreign").unwrap();
    // Created as a foreign process would: without the stack's settings.
    let name = shared_mem_schema::service_name(&ns, TorqueCommand::TOPIC);
    let key = AttributeKey::new(transport::SCHEMA_ATTRIBUTE.as_bytes()).unwrap();
    let version = AttributeValue::new(SCHEMA_VERSION.to_string().as_bytes()).unwrap();
    let attributes = AttributeSpecifier::new().define(&key, &version).unwrap();
    let _foreign = node
        .service_builder(&ServiceName::new(&name).unwrap())
        .publish_subscribe::<TorqueCommand>()
        .subscriber_max_buffer_size(8)
        .history_size(0)
        .enable_safe_overflow(true)
        .max_publishers(1)
        .max_subscribers(16)
        .create_with_attributes(&attributes)
        .unwrap();
    let err = Channel::<TorqueCommand>::open(&node, &ns)
        .err()
        .expect("a service allowing 16 readers must be refused");
    match &err {
        TransportError::ForeignSettings {
            what,
            found,
            expected,
            ..
        } => assert_eq!((*what, *found, *expected), ("subscribers", 16, 2)),
        e => panic!("wrong error: {e}"),
    }
}
