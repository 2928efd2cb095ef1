//! The `robot-model` command-line tool prints what the library computes, and
//! refuses bad input with a message.

mod common;

use robot_model::{LoadOptions, Model};
use std::process::Command;

fn run(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_robot-model"))
        .args(args)
        .output()
        .expect("run robot-model")
}

#[test]
fn prints_poses_jacobian_and_dynamics_as_json() {
    let urdf = common::crate_path("urdf/panda.urdf");
    let q = "0.1 -0.4 0.2 -2.0 0.3 1.7 0.5";
    let out = run(&[
        urdf.to_str().unwrap(),
        "--q",
        q,
        "--v",
        "0.1,0,0,0,0,0,0.2",
        "--frame",
        "peg_tip",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["nq"], 7);
    assert_eq!(json["jacobian"]["frame"], "peg_tip");

    // The numbers are the library's.
    let model = Model::from_urdf_file(&urdf, &LoadOptions::default()).unwrap();
    let mut data = model.create_data();
    let qv: Vec<f64> = q.split(' ').map(|s| s.parse().unwrap()).collect();
    let m = robot_model::crba(&model, &mut data, &qv).clone();
    for i in 0..7 {
        for j in 0..7 {
            let printed = json["mass_matrix"][i][j].as_f64().unwrap();
            assert!((printed - m[(i, j)]).abs() < 1e-12);
        }
    }
    let g = robot_model::gravity(&model, &mut data, &qv).clone();
    let rnea = json["rnea"].as_array().unwrap();
    let nle = json["nonlinear_effects"].as_array().unwrap();
    for i in 0..7 {
        assert!((json["gravity"][i].as_f64().unwrap() - g[i]).abs() < 1e-12);
        // a = 0: RNEA equals the nonlinear effects.
        assert!((rnea[i].as_f64().unwrap() - nle[i].as_f64().unwrap()).abs() < 1e-12);
    }
    let tip = json["frames"]
        .as_array()
        .unwrap()
        .iter()
        .find(|f| f["name"] == "peg_tip")
        .unwrap();
    robot_model::forward_kinematics(&model, &mut data, &qv);
    let pose = robot_model::frame_placement(&model, &data, model.frame_id("peg_tip").unwrap());
    assert!((tip["translation"][2].as_f64().unwrap() - pose.translation.z).abs() < 1e-12);
}

#[test]
fn accepts_any_serial_or_tree_urdf() {
    let urdf = common::crate_path("tests/fixtures/tree.urdf");
    let out = run(&[urdf.to_str().unwrap(), "--reference", "local"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json["nq"], 6);
    // Unbounded limits are printed as null, not as an invalid number.
    let elbow = json["joints"]
        .as_array()
        .unwrap()
        .iter()
        .find(|j| j["name"] == "elbow")
        .unwrap();
    assert!(elbow["limits"]["lower"].is_null());
    assert_eq!(json["meshes_not_found"][0], "meshes/does_not_exist.stl");
}

#[test]
fn bad_input_gets_a_clear_error() {
    let urdf = common::crate_path("urdf/iiwa14.urdf");
    let out = run(&[urdf.to_str().unwrap(), "--q", "0 0 0"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--q has 3 values, the robot has 7 joints"),
        "{err}"
    );

    let out = run(&[urdf.to_str().unwrap(), "--frame", "nope"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("no frame named 'nope'"));

    let out = run(&["/no/such.urdf"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("/no/such.urdf"));
}
