//! What the learner writes for other tools and later readers, read by
//! those tools' own code: a training run's TensorBoard event file, read by
//! TensorBoard's reader (`event_accumulator`), holds the same rows as its
//! CSV files; `run.json` records the commit, the host, the start time, the
//! command line and the resolved configuration, one entry per start (a
//! resumed run adds one); an exported policy's safetensors, loaded by
//! `safetensors.numpy` and run in NumPy as its spec says, acts as ours; every
//! channel of a fresh MCAP log is decoded by the official `mcap` reader with
//! `mcap-ros2-support`, each message by its own schema, to the values written.

use std::process::Command;

mod interop_venv;

/// The readers' interpreter ([`interop_venv::python`]).
fn interop_python() -> Option<std::path::PathBuf> {
    interop_venv::python(
        "tensorboard, safetensors.numpy, mcap_ros2.decoder, jsonschema",
        "tensorboard, safetensors, mcap-ros2-support and jsonschema are",
    )
}

/// Runs `script` with `args` under `py`; its stdout, parsed as JSON (its
/// stderr in the panic when it fails).
fn run_python<T: serde::de::DeserializeOwned>(
    py: &std::path::Path,
    script: &str,
    args: &[&std::ffi::OsStr],
) -> T {
    let out = interop_venv::run_ok(Command::new(py).args(["-c", script]).args(args));
    serde_json::from_slice(&out).unwrap()
}

const READ: &str = r#"
import json, sys
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
acc = EventAccumulator(sys.argv[1], size_guidance={"scalars": 0})
acc.Reload()
print(json.dumps({t: [[e.step, e.value] for e in acc.Scalars(t)] for t in acc.Tags()["scalars"]}))
"#;

/// Column `name` of a CSV file, as (env_steps, value) rows.
fn column(path: &std::path::Path, name: &str) -> Vec<(u64, f64)> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let steps = header.iter().position(|&h| h == "env_steps").unwrap();
    let col = header.iter().position(|&h| h == name).unwrap();
    lines
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[steps].parse().unwrap(), f[col].parse().unwrap())
        })
        .collect()
}

#[test]
fn a_policy_run_writes_tensorboard_scalars_and_its_provenance() {
    let dir = test_support::scratch_dir("runlog");
    let out = dir.path().join("run");
    let text = "num_envs = 1\nenv_steps = 40\n[policy]\nbatch_steps = 20\n\
                [env]\nmax_steps = 20\n[validation]\nevery = 1\nepisodes = 1\n";
    let mut run: learner::rl::run::TrainConfig = toml::from_str(text).unwrap();
    learner::rl::run::train(run.clone(), &out, false, &|| false).unwrap();
    run.env_steps = 60;
    learner::rl::run::train(run, &out, true, &|| false).unwrap();

    let starts: Vec<serde_json::Value> =
        serde_json::from_str(&std::fs::read_to_string(out.join("run.json")).unwrap()).unwrap();
    assert_eq!(starts.len(), 2, "one entry per start");
    for s in &starts {
        assert!(s["host"].as_str().is_some_and(|h| !h.is_empty()), "{s}");
        assert!(
            s["started"].as_str().is_some_and(|t| t.ends_with('Z')),
            "{s}"
        );
        assert!(s["argv"].as_array().is_some_and(|a| !a.is_empty()), "{s}");
        // The repository the test runs in is a git checkout.
        assert_eq!(s["commit"].as_str().map(str::len), Some(40), "{s}");
        assert!(s["dirty"].is_boolean(), "{s}");
    }
    assert_eq!(
        starts[1]["config"]["env_steps"], 60,
        "the resolved configuration"
    );

    let events: Vec<_> = std::fs::read_dir(&out)
        .unwrap()
        .filter_map(|e| {
            let n = e.unwrap().file_name().into_string().unwrap();
            n.starts_with("events.out.tfevents.").then_some(n)
        })
        .collect();
    assert_eq!(events.len(), 2, "one event file per start: {events:?}");
    let Some(py) = interop_python() else {
        return;
    };
    let scalars: serde_json::Value = run_python(&py, READ, &[out.as_os_str()]);
    for (csv, tag, col) in [
        ("curve.csv", "train/mean_normalised", "mean_normalised"),
        ("curve.csv", "train/kl", "kl"),
        (
            "validation.csv",
            "validation/completed_insertion",
            "completed_insertion",
        ),
        (
            "validation.csv",
            "validation/mean_normalised",
            "mean_normalised",
        ),
    ] {
        let want = column(&out.join(csv), col);
        let got: Vec<(u64, f64)> = scalars[tag]
            .as_array()
            .unwrap_or_else(|| panic!("no {tag} in {scalars}"))
            .iter()
            .map(|p| (p[0].as_u64().unwrap(), p[1].as_f64().unwrap()))
            .collect();
        assert_eq!(got.len(), want.len(), "{tag}: {got:?} vs {want:?}");
        for ((gs, gv), (ws, wv)) in got.iter().zip(&want) {
            assert_eq!(gs, ws, "{tag}");
            assert!(
                (gv - wv).abs() <= 1e-6 * wv.abs().max(1.0),
                "{tag}: {gv} vs {wv}"
            );
        }
    }
}

const ACT: &str = r#"
import json, sys
import numpy as np
from safetensors.numpy import load_file
t = load_file(sys.argv[1] + "/policy.safetensors")
spec = json.load(open(sys.argv[1] + "/policy-spec.json"))
out = []
for o in json.loads(sys.argv[2]):
    x = np.array(o)
    if spec["obs_norm_clip"] is not None:
        c = spec["obs_norm_clip"]
        x = np.clip((x - t["obs_norm.shift"]) * t["obs_norm.scale"], -c, c)
    for i in range(spec["layers"]):
        x = t[f"layers.{i}.weight"] @ x + t[f"layers.{i}.bias"]
        if i + 1 < spec["layers"]:
            x = np.tanh(x)
    out.append(x.tolist())
print(json.dumps(out))
"#;

#[test]
fn an_exported_policy_acts_in_numpy_as_it_does_here() {
    let dir = test_support::scratch_dir("interop-policy");
    let out = dir.path().join("run");
    let text = "num_envs = 1\nenv_steps = 40\n[policy]\nbatch_steps = 20\n\
                normalise_observations = true\n[env]\nmax_steps = 20\n";
    let run: learner::rl::run::TrainConfig = toml::from_str(text).unwrap();
    let c = learner::rl::run::train(run, &out, false, &|| false).unwrap();
    let policy = &c.state.policy;
    assert!(
        policy.obs_norm.is_some(),
        "the normalisation is exported too"
    );
    let d = learner::rl::export::from_checkpoint(&out.join("checkpoint.json"), true).unwrap();
    let export = dir.path().join("export");
    std::fs::create_dir_all(&export).unwrap();
    learner::rl::export::write_safetensors(&d.policy, &export).unwrap();
    // Observations unlike one another, some far outside the statistics.
    let dim = policy.sizes[0];
    let obs: Vec<Vec<f64>> = (0..5)
        .map(|k| {
            (0..dim)
                .map(|i| ((k * 7 + i * 3) % 11) as f64 * 0.3 - 1.5)
                .collect()
        })
        .collect();
    let Some(py) = interop_python() else {
        return;
    };
    let obs_json = serde_json::to_string(&obs).unwrap();
    let theirs: Vec<Vec<f64>> = run_python(&py, ACT, &[export.as_os_str(), obs_json.as_ref()]);
    for (o, t) in obs.iter().zip(&theirs) {
        let ours = policy.means(o);
        assert_eq!(ours.len(), t.len());
        for (a, b) in ours.iter().zip(t) {
            assert!((a - b).abs() < 1e-9, "ours {ours:?}, NumPy's {t:?}");
        }
    }
}

/// Every message of a log decoded by the official reader: CDR channels by
/// `mcap-ros2-support` from their `ros2msg` schema, JSON channels as JSON
/// validated by `jsonschema` against their own schema (encoding
/// `jsonschema`); anything else fails. Prints
/// {topic: [message as plain JSON, ...]}.
const DECODE_LOG: &str = r#"
import json, sys
import jsonschema
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

def plain(v):
    if hasattr(v, "__slots__"):
        return {k: plain(getattr(v, k)) for k in v.__slots__}
    if isinstance(v, (bytes, bytearray)):
        return list(v)
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if hasattr(v, "tolist"):
        return v.tolist()
    return v

factory = DecoderFactory()
out = {}
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f)
    for schema, channel, message in reader.iter_messages():
        if channel.message_encoding == "cdr":
            decode = factory.decoder_for(channel.message_encoding, schema)
            assert decode is not None, channel.topic
            value = plain(decode(message.data))
        elif channel.message_encoding == "json" and schema.encoding == "jsonschema":
            value = json.loads(message.data)
            # Each message against its channel's own schema, which must
            # describe its fields (not a bare "object").
            s = json.loads(schema.data)
            assert s.get("properties"), f"{channel.topic}: a schema without properties"
            jsonschema.validate(value, s)
        else:
            sys.exit(f"{channel.topic}: no decoder for {channel.message_encoding!r} / "
                     f"{schema.encoding if schema else None!r}")
        out.setdefault(channel.topic, []).append(value)
print(json.dumps(out))
"#;

#[test]
fn the_official_mcap_reader_decodes_every_channel_of_a_log() {
    use learner_node::log::{LogWriter, topics};
    use shared_mem_schema::{
        CameraFrame, ControllerStatus, EpisodeReport, Header, Message, PolicyAction, SensorFrame,
    };
    let dir = test_support::scratch_dir("interop-log");
    let path = dir.path().join("run.mcap");
    let mut w = LogWriter::create(&path).unwrap();
    // The configuration names the robot whose links the views place.
    let world = hw_sim::WorldConfig::default();
    let config = learner_node::log::config::RunConfig::new(
        learner_node::log::config::RunMode::Fast,
        world.clone(),
        learner_node::mix::EpisodePolicy::Heuristic,
        3,
        41,
    );
    w.config(0, &config).unwrap();
    w.event(
        0,
        &learner_node::log::events::Event::Reset(Box::new(learner_node::log::events::Reset {
            episode: 3,
            seed: 41,
            peg: world.task.peg,
            policy: learner_node::mix::EpisodePolicy::Heuristic,
            lockstep: None,
            world: None,
            hole_pos_m: [0.6, 0.05, 0.1],
            hole_quat_xyzw: [0.0, 0.0, 0.0, 1.0],
            hole_depth_m: 0.03,
        })),
    )
    .unwrap();
    w.event(
        0,
        &learner_node::log::events::Event::Stage {
            stage: hw_sim::Stage::Touched,
        },
    )
    .unwrap();
    let mut frames = Vec::new();
    for k in 0..120u64 {
        let mut f = *SensorFrame::boxed_zeroed();
        f.header = Header::new(k + 1, 7 + k, k * 1_000_000, 2);
        f.step = k;
        f.n_joints = 7;
        f.mode = 2;
        f.fault_code = (k % 5) as u32;
        for i in 0..7 {
            f.q[i] = 0.1 * i as f64 + 1e-3 * k as f64;
            f.tau_cmd[i] = -(i as f64) - 0.5;
            f.tau_sent[i] = -(i as f64) - 0.25;
        }
        f.ee_pos_m = [0.5, -0.25, 0.125 + 1e-4 * k as f64];
        f.ee_quat_xyzw = [1.0, 0.0, 0.0, 0.0];
        f.wrench = [1.5, -2.0, 30.0 + k as f64, 0.25, -0.125, 1e-9];
        w.sensor(&f).unwrap();
        frames.push(f);
    }
    let mut a = PolicyAction::new(5, 99, [0.001, -0.002, 0.0015, 0.04]);
    a.header.episode = 2;
    a.apply_at_step = 50;
    w.action(&a).unwrap();
    let mut s = *ControllerStatus::boxed_zeroed();
    s.header = Header::new(3, 4, 5_000_000, 2);
    s.cycles = 1234;
    s.mode = 3;
    s.fault_code = 2;
    s.command_result = 1;
    s.wakeup_latency.bins[7] = 42;
    s.action_latency.max_ns = 987_654;
    w.status(&s).unwrap();
    let mut e = *EpisodeReport::boxed_zeroed();
    e.header = Header::new(1, 2, 0, 2);
    e.seed = 77;
    e.s_m = [0.01, -0.02, 0.03];
    e.hole_quat_xyzw = [0.0, 0.0, 0.5f64.sqrt(), 0.5f64.sqrt()];
    e.message_len = shared_mem_schema::write_text(&mut e.message, "reset ok");
    w.episode(&e).unwrap();
    let (cw, ch) = (5u32, 3u32);
    let mut c = CameraFrame::boxed_zeroed();
    c.header = Header::new(1, 5, 50_000_000, 2);
    c.index = 9;
    c.calibration.width = cw;
    c.calibration.height = ch;
    c.calibration.focal_px = 154.5;
    c.calibration.principal_px = [2.5, 1.5];
    c.calibration.pose_quat_xyzw = [0.0, 0.0, 0.0, 1.0];
    for k in 0..(cw * ch) as usize {
        c.rgb[3 * k..3 * k + 3].copy_from_slice(&[k as u8, 100 + k as u8, 255 - k as u8]);
        c.depth_m[k] = 0.5 + k as f32 * 0.25;
    }
    w.camera(&c).unwrap();
    w.finish().unwrap();

    let Some(py) = interop_python() else {
        return;
    };
    let log: serde_json::Value = run_python(&py, DECODE_LOG, &[path.as_os_str()]);
    let f64s = |v: &serde_json::Value| -> Vec<f64> {
        v.as_array()
            .unwrap_or_else(|| panic!("not an array: {v}"))
            .iter()
            .map(|x| x.as_f64().unwrap())
            .collect()
    };
    let sensor = log[topics::SENSOR].as_array().expect("sensor frames");
    assert_eq!(sensor.len(), frames.len());
    for (m, f) in sensor.iter().zip(&frames) {
        assert_eq!(m["header"]["seq"], f.header.seq);
        assert_eq!(m["header"]["t_hw_ns"], f.header.t_hw_ns);
        assert_eq!(m["header"]["schema_version"], f.header.schema_version);
        assert_eq!(m["step"], f.step);
        assert_eq!(m["fault_code"], f.fault_code);
        assert_eq!(f64s(&m["q"]), f.q);
        assert_eq!(f64s(&m["tau_cmd"]), f.tau_cmd);
        assert_eq!(f64s(&m["ee_pos_m"]), f.ee_pos_m);
        assert_eq!(f64s(&m["wrench"]), f.wrench);
        assert_eq!(f64s(&m["tau_sent"]), f.tau_sent, "the last field too");
    }
    let action = &log[topics::ACTION][0];
    assert_eq!(action["header"]["seq"], 5);
    assert_eq!(action["apply_at_step"], 50);
    assert_eq!(f64s(&action["delta_pos_m"]), a.delta_pos_m);
    assert_eq!(action["delta_roll_rad"], a.delta_roll_rad);
    let status = &log[topics::STATUS][0];
    assert_eq!(status["cycles"], 1234);
    assert_eq!(status["mode"], 3);
    assert_eq!(status["fault_code"], 2);
    assert_eq!(status["command_result"], 1);
    assert_eq!(status["wakeup_latency"]["bins"][7], 42);
    assert_eq!(status["action_latency"]["max_ns"], 987_654);
    let report = &log[topics::EPISODE][0];
    assert_eq!(report["seed"], 77);
    assert_eq!(f64s(&report["s_m"]), e.s_m);
    assert_eq!(f64s(&report["hole_quat_xyzw"]), e.hole_quat_xyzw);
    let text: Vec<u8> = report["message"].as_array().unwrap()[..8]
        .iter()
        .map(|b| b.as_u64().unwrap() as u8)
        .collect();
    assert_eq!(text, b"reset ok");
    let camera = &log[topics::CAMERA][0];
    assert_eq!(camera["index"], 9);
    assert_eq!(camera["calibration"]["width"], cw);
    assert_eq!(f64s(&camera["calibration"]["principal_px"]), [2.5, 1.5]);
    let n = (cw * ch) as usize;
    let rgb: Vec<u8> = camera["rgb"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b.as_u64().unwrap() as u8)
        .collect();
    assert_eq!(rgb, c.rgb[..3 * n]);
    let depth: Vec<f32> = f64s(&camera["depth_m"]).iter().map(|&d| d as f32).collect();
    assert_eq!(depth, c.depth_m[..n]);
    // The views and the JSON channels decode too (their contents are
    // learner/tests/log.rs's).
    for topic in [
        topics::VIEW_RGB,
        topics::VIEW_TF,
        topics::VIEW_WRENCH,
        topics::EVENTS,
        topics::CONFIG,
        topics::VIEW_SCENE,
    ] {
        assert!(
            log[topic].as_array().is_some_and(|m| !m.is_empty()),
            "{topic}"
        );
    }
    assert_eq!(log[topics::CONFIG][0]["robot"], world.robot.as_str());
    // The scene: the arm's links and the peg at the configuration, the
    // box at the reset, each frame-locked to a frame /tf gives.
    let scene = log[topics::VIEW_SCENE].as_array().unwrap();
    assert_eq!(scene.len(), 2);
    let ids = |m: &serde_json::Value| -> Vec<String> {
        m["entities"]
            .as_array()
            .unwrap()
            .iter()
            .map(|e| e["id"].as_str().unwrap().to_string())
            .collect()
    };
    let first = ids(&scene[0]);
    assert!(first.contains(&"peg".to_string()), "{first:?}");
    assert!(
        first.iter().filter(|i| i.starts_with("arm/")).count() >= 8,
        "{first:?}"
    );
    assert_eq!(ids(&scene[1]), ["box"]);
    let walls = scene[1]["entities"][0]["cubes"].as_array().unwrap();
    assert_eq!(walls.len(), 5, "four walls and the hole's floor");
    // Every link of the robot, placed at the frame's joint angles: the
    // last frame's flange where the model puts it.
    let tf = log[topics::VIEW_TF]
        .as_array()
        .unwrap()
        .iter()
        .rev()
        .find(|m| m["transforms"].as_array().unwrap().len() > 1)
        .expect("a transform message with the arm's links");
    let links: Vec<&str> = tf["transforms"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["child_frame_id"].as_str().unwrap())
        .collect();
    let model = robot_model::descriptions::load(&world.robot).unwrap();
    for f in &model.frames {
        if f.kind == robot_model::FrameKind::Link {
            assert!(
                links.contains(&f.name.as_str()),
                "{} missing from {links:?}",
                f.name
            );
        }
    }
    assert!(links.len() >= 10, "{links:?}");
    let mut data = model.create_data();
    let last = frames.last().unwrap();
    robot_model::forward_kinematics(&model, &mut data, &last.q[..7]);
    let want = robot_model::frame_placement(&model, &data, model.frame_id("flange").unwrap());
    let flange = tf["transforms"]
        .as_array()
        .unwrap()
        .iter()
        .find(|t| t["child_frame_id"] == "flange")
        .unwrap();
    assert_eq!(flange["parent_frame_id"], "base");
    for (k, axis) in ["x", "y", "z"].iter().enumerate() {
        let got = flange["translation"][axis].as_f64().unwrap();
        assert!((got - want.translation.vector[k]).abs() < 1e-12, "{axis}");
    }
    shipped_layout_reads_this_log(&log);
    let ours = learner_node::log::LogReader::open(&path).unwrap();
    assert_eq!(
        ours.read_raw::<SensorFrame>(topics::SENSOR, None).unwrap(),
        frames
    );
    assert_eq!(ours.read_camera(None).unwrap()[0].depth_m, c.depth_m[..n]);
}

/// The shipped Foxglove layout (deploy/foxglove/vision-touch.json) fits a
/// log as the official reader decodes it (`log`: topic → messages): every
/// panel of its tree is configured, and every topic and message path its
/// panels name leads to a value in the log's first message on that topic.
fn shipped_layout_reads_this_log(log: &serde_json::Value) {
    let layout: serde_json::Value =
        serde_json::from_str(include_str!("../../deploy/foxglove/vision-touch.json")).unwrap();
    let configs = layout["configById"].as_object().unwrap();
    fn panels(node: &serde_json::Value, out: &mut Vec<String>) {
        match node {
            serde_json::Value::String(id) => out.push(id.clone()),
            n => {
                panels(&n["first"], out);
                panels(&n["second"], out);
            }
        }
    }
    let mut ids = Vec::new();
    panels(&layout["layout"], &mut ids);
    assert_eq!(ids.len(), configs.len());
    for id in &ids {
        assert!(configs.contains_key(id), "{id} has no configuration");
    }
    fn paths(v: &serde_json::Value, out: &mut Vec<String>) {
        match v {
            serde_json::Value::Object(m) => {
                for (k, x) in m {
                    match (k.as_str(), x) {
                        (
                            "value" | "topicPath" | "imageTopic" | "calibrationTopic",
                            serde_json::Value::String(p),
                        ) => out.push(p.clone()),
                        ("topics", serde_json::Value::Object(t)) => out.extend(t.keys().cloned()),
                        _ => paths(x, out),
                    }
                }
            }
            serde_json::Value::Array(a) => a.iter().for_each(|x| paths(x, out)),
            _ => {}
        }
    }
    let mut all = Vec::new();
    paths(&layout["configById"], &mut all);
    assert!(all.len() >= 10, "{all:?}");
    for p in all {
        let (topic, fields) = p.split_once('.').unwrap_or((&p, ""));
        let first = &log[topic][0];
        assert!(!first.is_null(), "{p}: the log has no {topic}");
        let mut v = first;
        for f in fields.split('.').filter(|f| !f.is_empty()) {
            v = &v[f];
            assert!(!v.is_null(), "{p}: no field {f} in {topic}'s messages");
        }
    }
}
