//! When OSC asks for more torque than the robot has, the QP filter keeps the
//! direction of the Cartesian force far better than per-joint clipping.

mod common;

use common::panda;
use nalgebra::{DMatrix, DVector, Matrix6xX, Vector3, Vector6};
use robot_model::Reference;
use rt_controller::osc::{self, OscData, OscInputs};
use rt_controller::qp::{QpFilter, QpProblem};
use rt_controller::{QpConfig, QpOutcome};
use test_support::Uniform;

fn angle(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    (a.dot(b) / (a.norm() * b.norm())).clamp(-1.0, 1.0).acos()
}

fn percentile(v: &mut [f64], p: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * p).round() as usize]
}

#[test]
fn saturated_qp_keeps_the_force_direction_far_better_than_clipping() {
    let model = panda();
    let nv = model.nv();
    let ee = model.frame_id("peg_tip").unwrap();
    let mut rm = model.create_data();
    let mut jac = Matrix6xX::zeros(nv);
    let mut od = OscData::new(nv);
    let cfg = QpConfig::default();
    let tau_max = model.effort_limits();
    let (lo, hi) = (model.lower_limits(), model.upper_limits());
    let mut rng = test_support::rng(42);
    let mut qp_err = Vec::new();
    let mut clip_err = Vec::new();
    let mut qp_filter: Option<QpFilter> = None;
    let wide = DVector::from_element(nv, 1e9);
    let mut cases = 0;
    while cases < 300 {
        let q: Vec<f64> = (0..nv)
            .map(|i| rng.uniform(lo[i] + 0.2, hi[i] - 0.2))
            .collect();
        let v = vec![0.0; nv];
        robot_model::crba(&model, &mut rm, &q);
        let mass = rm.mass.clone();
        let mut chol = DMatrix::zeros(nv, nv);
        robot_model::cholesky_factor(&mass, &mut chol).unwrap();
        let h = robot_model::nonlinear_effects(&model, &mut rm, &q, &v).clone();
        robot_model::forward_kinematics(&model, &mut rm, &q);
        robot_model::frame_jacobian(&model, &rm, ee, Reference::Base, &mut jac);
        // A pure force demand (no moment), in a random direction.
        let dir = Vector3::new(
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
            rng.uniform(-1.0, 1.0),
        )
        .normalize();
        let a_u = Vector6::new(dir.x, dir.y, dir.z, 0.0, 0.0, 0.0);
        let rest = q.clone();
        let zero = Vector6::zeros();
        let run = |od: &mut OscData, a_u: &Vector6<f64>| {
            let inputs = OscInputs {
                q: &q,
                v: &v,
                mass: &mass,
                chol: &chol,
                h: &h,
                jac: &jac,
                jdot_v: &zero,
                a_u,
                rest_q: &rest,
            };
            let params = osc::OscParams {
                singular_eps: 0.02,
                eigen_max_iter: 180,
                null_kp: 0.0,
                null_kv: 0.0,
            };
            osc::compute(od, &inputs, &params).expect("OSC at a finite state");
        };
        run(&mut od, &a_u);
        if od.min_sigma < 0.02 {
            continue; // the regularised Λ is not the exact one there
        }
        // Scale the demand so the worst joint asks 1.5–5× its limit.
        let ratio = (0..nv)
            .map(|i| (od.tau[i] - h[i]).abs() / tau_max[i])
            .fold(0.0, f64::max);
        let target = rng.uniform(1.5, 5.0);
        let a_u = a_u * (target / ratio);
        run(&mut od, &a_u);
        let over = (0..nv)
            .map(|i| od.tau[i].abs() / tau_max[i])
            .fold(0.0, f64::max);
        if over <= 1.0 {
            continue; // gravity happened to help: not saturated
        }
        let filter = qp_filter.get_or_insert_with(|| QpFilter::new(nv, &cfg, &od.minv));
        let a_osc = &od.minv * (&od.tau - &h);
        let mut out = DVector::zeros(nv);
        let outcome = filter.filter(
            &QpProblem {
                jbar: &od.jbar,
                task_force: &od.force,
                lambda_inv: &od.lambda_inv,
                null_t: &od.null_t,
                minv: &od.minv,
                tau_osc: &od.tau,
                a_osc: &a_osc,
                tau_lo: &(-&tau_max),
                tau_hi: &tau_max,
                acc_lo: &(-&wide),
                acc_hi: &wide,
            },
            &mut out,
        );
        assert!(matches!(outcome, QpOutcome::Solved { .. }), "{outcome:?}");
        let clipped = DVector::from_fn(nv, |i, _| od.tau[i].clamp(-tau_max[i], tau_max[i]));
        let force = |tau: &DVector<f64>| -> Vector3<f64> {
            let f = od.jbar.transpose() * (tau - &h);
            Vector3::new(f[0], f[1], f[2])
        };
        let wanted = force(&od.tau);
        // J̄ᵀ Jᵀ f = f: the OSC torques produce exactly the task force Λ a_u.
        let f = Vector3::new(od.force[0], od.force[1], od.force[2]);
        assert!(
            angle(&wanted, &f) < 1e-6,
            "OSC torques carry the task force"
        );
        for i in 0..nv {
            assert!(out[i].abs() <= tau_max[i] + 1e-9);
        }
        qp_err.push(angle(&force(&out), &wanted).to_degrees());
        clip_err.push(angle(&force(&clipped), &wanted).to_degrees());
        cases += 1;
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let (mq, mc) = (mean(&qp_err), mean(&clip_err));
    let (p95q, p95c) = (
        percentile(&mut qp_err, 0.95),
        percentile(&mut clip_err, 0.95),
    );
    println!("force direction error over {cases} saturated cases, degrees:");
    println!(
        "  QP filter: mean {mq:.2}, p95 {p95q:.2}, max {:.2}",
        qp_err.last().unwrap()
    );
    println!(
        "  clipping:  mean {mc:.2}, p95 {p95c:.2}, max {:.2}",
        clip_err.last().unwrap()
    );
    assert!(mq < 0.1 * mc, "QP mean {mq:.2}° vs clipping {mc:.2}°");
    assert!(
        p95q < 0.1 * p95c,
        "QP p95 {p95q:.2}° vs clipping {p95c:.2}°"
    );
}
