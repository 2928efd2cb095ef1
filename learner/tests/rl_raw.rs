//! The raw-input baseline's observer (`observation = { raw = { side } }`):
//! the camera frame pooled, the wrench window and the proprioception, and
//! nothing privileged.

use learner::rl::RlEnv;
use learner::rl::observe::ObservationKind;
use learner::rl::raw::RawSpec;
use nalgebra::Isometry3;

const SIDE: usize = 8;

/// The value at `(row, col)` of channel `k` (0–2 RGB / 255, 3 depth)
/// pooled to `side` from the frame by hand: the mean of the pixels that
/// fall into the cell (pixel row y is in cell row y·side/h; side ≤ the frame).
fn pooled_by_hand(
    cam: &shared_mem_schema::CameraFrame,
    side: usize,
    k: usize,
    row: usize,
    col: usize,
) -> f64 {
    let (w, h) = (
        cam.calibration.width as usize,
        cam.calibration.height as usize,
    );
    let (mut sum, mut n) = (0.0, 0.0);
    for y in (0..h).filter(|y| y * side / h == row) {
        for x in (0..w).filter(|x| x * side / w == col) {
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
    // A few steps down (still in free space): a frame of a moved arm.
    for _ in 0..4 {
        env.step(&[0.0, 0.0, -1.0, 0.0], true).unwrap();
    }
    let v = env.view().expect("a view after a step");
    let mut a = vec![f64::NAN; dim];
    observer.observe(std::slice::from_ref(&v), &mut a);
    assert!(a.iter().all(|x| x.is_finite()));
    let cam = v.camera.expect("rendered");
    for (k, row, col) in [(0, 0, 0), (1, 7, 7), (2, 3, 5), (3, 4, 4), (3, 0, 7)] {
        let want = pooled_by_hand(cam, SIDE, k, row, col);
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
    // A side that does not divide the frame (128 px into 12): uneven cells.
    let twelve = ObservationKind::Raw(RawSpec { side: 12 })
        .observer()
        .unwrap();
    let mut u = vec![0.0; twelve.dim()];
    twelve.observe(std::slice::from_ref(&v), &mut u);
    for (k, row, col) in [(0, 0, 0), (3, 11, 11), (2, 5, 6), (3, 6, 1)] {
        let want = pooled_by_hand(cam, 12, k, row, col);
        let got = u[k * 144 + row * 12 + col];
        assert!(
            (got - want).abs() < 1e-9,
            "side 12, channel {k}: {got} vs {want}"
        );
    }
    // A side above the frame's repeats pixels: no cell is empty or blank.
    let big = ObservationKind::Raw(RawSpec { side: 200 })
        .observer()
        .unwrap();
    let mut g = vec![f64::NAN; big.dim()];
    big.observe(std::slice::from_ref(&v), &mut g);
    assert!(g.iter().all(|x| x.is_finite()) && big.rejected() == 0);
    // Each cell is one pixel then: row ⌈r·h/side⌉ (at most the last).
    for (row, col) in [(0, 0), (1, 1), (77, 150), (199, 199)] {
        let pixel = |rc: usize| (rc * 128).div_ceil(200).min(127);
        let depth = f64::from(cam.depth_m[pixel(row) * 128 + pixel(col)]).max(0.0);
        assert_eq!(
            g[3 * 40_000 + row * 200 + col],
            depth,
            "cell ({row}, {col})"
        );
    }
    // The proprioception closes the vector.
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
    // The wrench window: oldest first, force / 10 N, moments as read; a
    // history of 3 readings repeats its oldest in front, as the encoder's.
    let reading = |i: usize| -> [f64; 6] { std::array::from_fn(|k| (10 * i + k) as f64 + 0.5) };
    for pushed in [3, 40] {
        let mut history = learner_node::policy::WrenchHistory::default();
        for i in 0..pushed {
            history.push(reading(i));
        }
        let view = learner::rl::observe::ObsView {
            wrench: &history,
            ..v
        };
        observer.observe(std::slice::from_ref(&view), &mut d);
        let window = &d[4 * plane..4 * plane + 6 * 32];
        for (row, got) in window.chunks_exact(6).enumerate() {
            // Of 3 readings, row r holds reading max(0, r − 29); of 40,
            // reading r + 8 (the newest 32).
            let i = if pushed == 3 {
                row.saturating_sub(29)
            } else {
                row + 8
            };
            for (k, (g, r)) in got.iter().zip(reading(i)).enumerate() {
                let want = if k < 3 { r / 10.0 } else { r };
                assert_eq!(*g, want, "{pushed} readings, row {row}, component {k}");
            }
        }
    }
}

#[test]
fn a_raw_observer_of_no_side_and_its_export_are_refused_by_name() {
    for side in [0, learner::rl::raw::MAX_SIDE + 1] {
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
