//! The raw-input baseline's observer (`observation = { raw = { side } }`):
//! the camera frame pooled, the wrench window and the proprioception, and
//! nothing privileged.

use learner::rl::observe::ObservationKind;
use learner::rl::raw::RawSpec;
use learner::rl::RlEnv;
use nalgebra::Isometry3;

const SIDE: usize = 8;

/// The value at `(row, col)` of pooled channel `k` (0–2 RGB / 255, 3
/// depth) computed from the frame by hand.
fn pooled_by_hand(cam: &shared_mem_schema::CameraFrame, k: usize, row: usize, col: usize) -> f64 {
    let (w, h) = (
        cam.calibration.width as usize,
        cam.calibration.height as usize,
    );
    let (mut sum, mut n) = (0.0, 0.0);
    for y in row * h / SIDE..(row + 1) * h / SIDE {
        for x in col * w / SIDE..(col + 1) * w / SIDE {
            let p = y * w + x;
            sum += if k < 3 {
                f64::from(cam.rgb[3 * p + k]) / 255.0
            } else {
                f64::from(cam.depth_m[p]).max(0.0)
            };
            n += 1.0;
        }
    }
    sum / n
}

#[test]
fn the_raw_observer_pools_the_camera_and_reads_nothing_privileged() {
    let observer = ObservationKind::Raw(RawSpec { side: SIDE })
        .observer()
        .unwrap();
    let plane = SIDE * SIDE;
    let dim = 4 * plane + 6 * 32 + 8;
    assert_eq!(observer.dim(), dim);
    assert!(observer.needs_camera());
    let mut env = RlEnv::new(&Default::default()).unwrap();
    env.reset(3, true).unwrap();
    // Down onto the box for a few steps: the wrench window holds contact.
    for _ in 0..4 {
        env.step(&[0.0, 0.0, -1.0, 0.0], true).unwrap();
    }
    let v = env.view().expect("a view after a step");
    let mut a = vec![f64::NAN; dim];
    observer.observe(std::slice::from_ref(&v), &mut a);
    assert!(a.iter().all(|x| x.is_finite()));
    let cam = v.camera.expect("rendered");
    for (k, row, col) in [(0, 0, 0), (1, 7, 7), (2, 3, 5), (3, 4, 4), (3, 0, 7)] {
        let want = pooled_by_hand(cam, k, row, col);
        let got = a[k * plane + row * SIDE + col];
        assert!(
            (got - want).abs() < 1e-9,
            "channel {k} ({row}, {col}): {got} vs {want}"
        );
    }
    assert!(
        a[3 * plane..4 * plane].iter().any(|&d| d > 0.1),
        "depth seen"
    );
    // The newest wrench reading (force / 10 N, moment as read) and the
    // proprioception close the vector.
    let newest = v.wrench.ordered().last().unwrap();
    let w = &a[4 * plane + 31 * 6..4 * plane + 32 * 6];
    for k in 0..6 {
        let want = if k < 3 { newest[k] / 10.0 } else { newest[k] };
        assert!((w[k] - want).abs() < 1e-12, "wrench {k}");
    }
    let proprio = v.obs.proprio.to_array();
    for (got, want) in a[dim - 8..].iter().zip(proprio) {
        assert_eq!(*got, f64::from(want));
    }
    // Nothing privileged: another task state, hole pose and symmetry give
    // the same observation.
    let mut task = *v.task;
    task.s_m.x += 0.05;
    task.s_m.z -= 0.02;
    task.s_psi_rad += 0.3;
    let hole = Isometry3::translation(0.3, -0.2, 0.1);
    let other = learner::rl::observe::ObsView {
        task: &task,
        hole_pose: &hole,
        symmetry: 7,
        ..v
    };
    let mut b = vec![0.0; dim];
    observer.observe(std::slice::from_ref(&other), &mut b);
    assert_eq!(a, b, "the raw observation read privileged state");
    // Without a camera frame the image is zeros and counted; the rest stays.
    let blind = learner::rl::observe::ObsView { camera: None, ..v };
    let mut c = vec![f64::NAN; dim];
    observer.observe(std::slice::from_ref(&blind), &mut c);
    assert!(c[..4 * plane].iter().all(|&x| x == 0.0));
    assert_eq!(c[4 * plane..], a[4 * plane..]);
    assert_eq!(observer.rejected(), 1);
    // Another box position is another image.
    let mut env2 = RlEnv::new(&Default::default()).unwrap();
    env2.reset(4, true).unwrap();
    for _ in 0..4 {
        env2.step(&[0.0, 0.0, -1.0, 0.0], true).unwrap();
    }
    let mut d = vec![0.0; dim];
    observer.observe(std::slice::from_ref(&env2.view().unwrap()), &mut d);
    assert_ne!(a[..4 * plane], d[..4 * plane], "the scene moved");
}

#[test]
fn a_raw_observer_of_no_side_and_its_export_are_refused_by_name() {
    for side in [0, 129] {
        let e = ObservationKind::Raw(RawSpec { side })
            .observer()
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("observation.raw.side"), "{e}");
    }
    let mut rng = stack_common::rng::seeded(1, 0);
    let policy = learner::rl::GaussianPolicy::new(4 * 64 + 200, &[8], 4, 0.0, &mut rng);
    let e = learner::rl::export::policy_file(
        &policy,
        &ObservationKind::Raw(RawSpec { side: 8 }),
        Default::default(),
        hw_sim::PegShape::Square,
        "test".into(),
    )
    .unwrap_err()
    .to_string();
    assert!(
        e.contains("raw inputs") && e.contains("no deployed format"),
        "{e}"
    );
    // The configuration's spelling.
    let kind: ObservationKind = toml::from_str::<toml::Table>(
        "observation = { raw = { side = 16 } }",
    )
    .unwrap()["observation"]
        .clone()
        .try_into()
        .unwrap();
    assert_eq!(kind, ObservationKind::Raw(RawSpec { side: 16 }));
}
