//! Malformed descriptions get an error naming the element at fault; odd but
//! valid ones (missing meshes, a tree) load.

mod common;

use robot_model::{LoadOptions, MissingLimits, Model, ModelError, Shape};

fn load(body: &str) -> Result<Model, ModelError> {
    Model::from_urdf_str(
        &format!("<robot name=\"r\">{body}</robot>"),
        &LoadOptions::default(),
    )
}

const TWO_LINKS: &str = r#"<link name="a"/><link name="b"><inertial><mass value="1"/>
    <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>"#;

fn revolute(name: &str, parent: &str, child: &str, origin: &str) -> String {
    format!(
        r#"<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>
        {origin}<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="10" velocity="1"/></joint>"#
    )
}

fn message(r: Result<Model, ModelError>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => e.to_string(),
    }
}

#[test]
fn missing_parent_link_is_named() {
    let err = load(&format!("{TWO_LINKS}{}", revolute("j", "ghost", "b", "")));
    assert!(matches!(
        err,
        Err(ModelError::MissingLink { role: "parent", .. })
    ));
    let msg = message(load(&format!(
        "{TWO_LINKS}{}",
        revolute("j", "ghost", "b", "")
    )));
    assert!(msg.contains("'j'") && msg.contains("'ghost'"), "{msg}");
}

#[test]
fn missing_child_link_is_named() {
    let msg = message(load(&format!(
        "{TWO_LINKS}{}",
        revolute("j", "a", "nowhere", "")
    )));
    assert!(msg.contains("child link 'nowhere'"), "{msg}");
}

#[test]
fn closed_loop_is_rejected() {
    // a → b → a: every link has a parent, there is no root.
    let body = format!(
        "{TWO_LINKS}{}{}",
        revolute("j1", "a", "b", ""),
        revolute("j2", "b", "a", "")
    );
    assert!(
        matches!(load(&body), Err(ModelError::Loop { .. })),
        "{:?}",
        load(&body).err()
    );
    // A link with two parents closes a loop too.
    let body = format!(
        r#"{TWO_LINKS}<link name="c"/>{}{}{}"#,
        revolute("j1", "a", "b", ""),
        revolute("j2", "b", "c", ""),
        revolute("j3", "a", "c", "")
    );
    let msg = message(load(&body));
    assert!(
        msg.contains("link 'c'") && msg.contains("'j2'") && msg.contains("'j3'"),
        "{msg}"
    );
    // A cycle detached from the root.
    let body = format!(
        r#"{TWO_LINKS}<link name="c"/>{}{}"#,
        revolute("j1", "b", "c", ""),
        revolute("j2", "c", "b", "")
    );
    let msg = message(load(&body));
    assert!(msg.contains("\"b\"") && msg.contains("\"c\""), "{msg}");
}

#[test]
fn unknown_joint_type_is_rejected() {
    let body = format!(
        r#"{TWO_LINKS}<joint name="j" type="telescopic"><parent link="a"/><child link="b"/></joint>"#
    );
    let msg = message(load(&body));
    assert!(msg.contains("telescopic"), "{msg}");
}

#[test]
fn unsupported_joint_type_is_named() {
    let body = format!(
        r#"{TWO_LINKS}<joint name="free" type="floating"><parent link="a"/><child link="b"/></joint>"#
    );
    let msg = message(load(&body));
    assert!(msg.contains("'free'") && msg.contains("floating"), "{msg}");
}

#[test]
fn nan_in_origin_is_rejected() {
    let body = format!(
        "{TWO_LINKS}{}",
        revolute("j", "a", "b", r#"<origin xyz="0 nan 0" rpy="0 0 0"/>"#)
    );
    let msg = message(load(&body));
    assert!(
        msg.contains("joint 'j' <origin>") && msg.contains("xyz"),
        "{msg}"
    );
    let body = format!(
        "{TWO_LINKS}{}",
        revolute("j", "a", "b", r#"<origin xyz="0 0 0" rpy="inf 0 0"/>"#)
    );
    assert!(message(load(&body)).contains("rpy"));
}

#[test]
fn bad_inertial_values_are_named() {
    let body = r#"<link name="a"/><link name="b"><inertial><mass value="-1"/>
        <inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>"#
        .to_string()
        + &revolute("j", "a", "b", "");
    let msg = message(load(&body));
    assert!(
        msg.contains("link 'b' <inertial>") && msg.contains("mass"),
        "{msg}"
    );
}

#[test]
fn zero_axis_is_rejected() {
    let body = format!(
        r#"{TWO_LINKS}<joint name="j" type="continuous"><parent link="a"/><child link="b"/><axis xyz="0 0 0"/></joint>"#
    );
    assert!(message(load(&body)).contains("joint 'j' <axis>"));
}

#[test]
fn missing_limit_is_rejected_or_unlimited_by_choice() {
    let body = format!(
        r#"{TWO_LINKS}<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/></joint>"#
    );
    let msg = message(load(&body));
    assert!(
        msg.contains("joint 'j'") && msg.contains("<limit>"),
        "{msg}"
    );
    let opts = LoadOptions {
        missing_limits: MissingLimits::Unlimited,
    };
    let model = Model::from_urdf_str(&format!("<robot name=\"r\">{body}</robot>"), &opts).unwrap();
    let l = model.joints[1].limits;
    // Never a joint locked at zero.
    assert!(l.lower == f64::NEG_INFINITY && l.upper == f64::INFINITY);
    assert!(l.effort == f64::INFINITY && l.velocity == f64::INFINITY);
}

#[test]
fn inverted_limits_are_rejected() {
    let body = format!(
        r#"{TWO_LINKS}<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>
        <limit lower="1" upper="-1" effort="1" velocity="1"/></joint>"#
    );
    assert!(message(load(&body)).contains("upper is below lower"));
}

#[test]
fn duplicate_names_are_rejected() {
    let msg = message(load(r#"<link name="a"/><link name="a"/>"#));
    assert!(msg.contains("duplicate link name 'a'"), "{msg}");
}

#[test]
fn several_roots_are_rejected() {
    let msg = message(load(r#"<link name="a"/><link name="b"/>"#));
    assert!(msg.contains("several root links"), "{msg}");
}

#[test]
fn missing_file_and_bad_xml_are_reported() {
    let err =
        Model::from_urdf_file("/nonexistent/robot.urdf", &LoadOptions::default()).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/robot.urdf"), "{err}");
    let err = Model::from_urdf_str(
        "<robot name=\"r\"><link name=\"a\">",
        &LoadOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(err, ModelError::Parse { .. }), "{err}");
}

#[test]
fn missing_meshes_do_not_prevent_loading() {
    let model = Model::from_urdf_file(
        common::crate_path("tests/fixtures/tree.urdf"),
        &LoadOptions::default(),
    )
    .unwrap();
    let mesh = model
        .geometries
        .iter()
        .find_map(|g| match &g.shape {
            Shape::Mesh {
                filename,
                resolved,
                scale,
            } => Some((filename.clone(), resolved.clone(), *scale)),
            _ => None,
        })
        .expect("the fixture has a mesh");
    assert_eq!(mesh.0, "meshes/does_not_exist.stl");
    assert!(mesh.1.is_none());
    assert_eq!(mesh.2, [0.001; 3]);
}

#[test]
fn tree_structure_is_kept() {
    let model = Model::from_urdf_file(
        common::crate_path("tests/fixtures/tree.urdf"),
        &LoadOptions::default(),
    )
    .unwrap();
    assert_eq!(model.nv(), 6);
    let side = model.joint_id("side").unwrap();
    let slide = model.joint_id("slide").unwrap();
    let elbow = model.joint_id("elbow").unwrap();
    assert_eq!(model.joints[side].parent, slide);
    assert!(!model.supports(side, elbow));
    // The fixed bracket's mass is lumped into the shoulder's body.
    let shoulder = model.joint_id("shoulder").unwrap();
    assert!((model.inertias[shoulder].mass - 1.9).abs() < 1e-12);
    assert_eq!(model.joints[elbow].limits.lower, f64::NEG_INFINITY);
}

#[test]
fn extra_frames_can_be_added() {
    let mut model = Model::from_urdf_file(
        common::crate_path("urdf/panda.urdf"),
        &LoadOptions::default(),
    )
    .unwrap();
    let offset = nalgebra::Isometry3::translation(0.0, 0.0, 0.05);
    let id = model.add_frame("long_tip", "peg_tip", &offset).unwrap();
    let mut data = model.create_data();
    let q = model.neutral_configuration();
    robot_model::forward_kinematics(&model, &mut data, q.as_slice());
    let tip = robot_model::frame_placement(&model, &data, model.frame_id("peg_tip").unwrap());
    let long = robot_model::frame_placement(&model, &data, id);
    assert!(((tip * offset).translation.vector - long.translation.vector).norm() < 1e-12);
    assert!(matches!(
        model.add_frame("long_tip", "peg_tip", &offset),
        Err(ModelError::DuplicateName { .. })
    ));
    assert!(matches!(
        model.add_frame("x", "nope", &offset),
        Err(ModelError::UnknownFrame(_))
    ));
}

#[test]
fn shipped_robots_have_the_frames_the_stack_uses() {
    for (name, model) in common::robots().into_iter().take(2) {
        assert_eq!(model.nv(), 7, "{name}");
        for frame in ["flange", "ft_sensor", "peg_tip"] {
            model
                .frame_id(frame)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
        }
        let collisions = model
            .geometries
            .iter()
            .filter(|g| g.role == robot_model::GeometryRole::Collision)
            .count();
        assert!(
            collisions >= 8,
            "{name}: every link needs a collision primitive"
        );
        for j in &model.joints[1..] {
            let l = j.limits;
            assert!(
                l.lower.is_finite()
                    && l.upper.is_finite()
                    && l.effort.is_finite()
                    && l.velocity.is_finite()
            );
        }
    }
}
