//! The robot descriptions the rest of the stack loads by path exist, load,
//! and agree with each other on the frames the controller and simulator use.

use robot_model::{LoadOptions, Model, forward_kinematics, frame_placement};

#[test]
fn shipped_descriptions_load_from_the_workspace_root() {
    for file in ["panda.urdf", "iiwa14.urdf"] {
        let path = tests::workspace_root().join("robot-model/urdf").join(file);
        let model = Model::from_urdf_file(&path, &LoadOptions::default())
            .unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        let mut data = model.create_data();
        let q = model.neutral_configuration();
        forward_kinematics(&model, &mut data, q.as_slice());
        let flange = frame_placement(&model, &data, model.frame_id("flange").unwrap());
        let sensor = frame_placement(&model, &data, model.frame_id("ft_sensor").unwrap());
        let tip = frame_placement(&model, &data, model.frame_id("peg_tip").unwrap());
        // flange → sensor → tip are stacked along the flange's z axis.
        let z = flange.rotation * nalgebra::Vector3::z();
        let d1 = sensor.translation.vector - flange.translation.vector;
        let d2 = tip.translation.vector - sensor.translation.vector;
        assert!((d1 - 0.04 * z).norm() < 1e-12, "{file}");
        assert!((d2 - 0.08 * z).norm() < 1e-12, "{file}");
        // Arms of 14 and 16 kg or so, not grams or tonnes.
        assert!(
            (10.0..40.0).contains(&model.moving_mass()),
            "{file}: {}",
            model.moving_mass()
        );
    }
}
