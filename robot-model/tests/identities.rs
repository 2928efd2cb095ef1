//! Identities that any correct rigid-body implementation satisfies, over many
//! random states of the Panda, the iiwa and a tree with every joint kind.

mod common;

use common::{axpy, robots};
use nalgebra::{DMatrix, DVector, Matrix6xX};
use robot_model::spatial::log3;
use robot_model::*;
use test_support::{RngExt, Uniform};

const SAMPLES: usize = 200;

fn dv(x: &[f64]) -> DVector<f64> {
    DVector::from_column_slice(x)
}

#[test]
fn mass_matrix_is_symmetric_positive_definite() {
    for (name, model) in robots() {
        let mut data = model.create_data();
        let mut rng = test_support::rng(1);
        for _ in 0..SAMPLES {
            let q = common::random_config(&mut rng, &model);
            let m = crba(&model, &mut data, &q).clone();
            assert!(
                (&m - m.transpose()).amax() < 1e-12,
                "{name}: M not symmetric"
            );
            let eig = m.symmetric_eigenvalues();
            assert!(
                eig.min() > 0.0,
                "{name}: M not positive definite, eigenvalues {eig}"
            );
        }
    }
}

#[test]
fn rnea_gravity_mass_matrix_and_nle_agree() {
    for (name, model) in robots() {
        let nv = model.nv();
        let mut data = model.create_data();
        let mut rng = test_support::rng(2);
        let zero = vec![0.0; nv];
        for _ in 0..SAMPLES {
            let q = common::random_config(&mut rng, &model);
            let v = rng.uniform_vec(nv, -2.0, 2.0);
            let a = rng.uniform_vec(nv, -5.0, 5.0);
            let g = gravity(&model, &mut data, &q).clone();
            let tau0 = rnea(&model, &mut data, &q, &zero, &zero).clone();
            assert!((&tau0 - &g).amax() < 1e-10, "{name}: RNEA(q,0,0) != g(q)");
            let tau_a = rnea(&model, &mut data, &q, &zero, &a).clone();
            let m = crba(&model, &mut data, &q).clone();
            let ma = &m * dv(&a);
            assert!(
                (&tau_a - &g - &ma).amax() < 1e-9,
                "{name}: RNEA(q,0,a) - g != M a"
            );
            let h = nonlinear_effects(&model, &mut data, &q, &v).clone();
            let tau_v = rnea(&model, &mut data, &q, &v, &zero).clone();
            assert!((&h - &tau_v).amax() < 1e-10, "{name}: nle != RNEA(q,v,0)");
            let c = coriolis_matrix(&model, &mut data, &q, &v).clone();
            let cv = &c * dv(&v);
            assert!(
                (&cv - (&h - &g)).amax() < 1e-9,
                "{name}: C v != h - g: {}",
                (&cv - (&h - &g)).amax()
            );
            let full = rnea(&model, &mut data, &q, &v, &a).clone();
            assert!(
                (&full - (&ma + &h)).amax() < 1e-9,
                "{name}: RNEA != M a + h"
            );
        }
    }
}

#[test]
fn coriolis_makes_mdot_minus_2c_skew_symmetric() {
    let eps = 1e-6;
    for (name, model) in robots() {
        let nv = model.nv();
        let mut data = model.create_data();
        let mut rng = test_support::rng(3);
        for _ in 0..50 {
            let q = common::random_config(&mut rng, &model);
            let v = rng.uniform_vec(nv, -2.0, 2.0);
            let mp = crba(&model, &mut data, &axpy(&q, eps, &v)).clone();
            let mm = crba(&model, &mut data, &axpy(&q, -eps, &v)).clone();
            let mdot = (mp - mm) / (2.0 * eps);
            let c = coriolis_matrix(&model, &mut data, &q, &v).clone();
            let s = &mdot - 2.0 * &c;
            let err = (&s + s.transpose()).amax();
            assert!(err < 1e-6, "{name}: Mdot - 2C not skew (err {err})");
        }
    }
}

#[test]
fn forward_dynamics_inverts_rnea() {
    for (name, model) in robots() {
        let nv = model.nv();
        let mut data = model.create_data();
        let mut rng = test_support::rng(4);
        for _ in 0..SAMPLES {
            let q = common::random_config(&mut rng, &model);
            let v = rng.uniform_vec(nv, -2.0, 2.0);
            let a = rng.uniform_vec(nv, -5.0, 5.0);
            let tau: Vec<f64> = rnea(&model, &mut data, &q, &v, &a)
                .iter()
                .copied()
                .collect();
            let acc = forward_dynamics(&model, &mut data, &q, &v, &tau)
                .unwrap()
                .clone();
            let err = (acc - dv(&a)).amax();
            assert!(err < 1e-8, "{name}: forward dynamics error {err}");
        }
    }
}

/// Finite-difference Jacobian of a frame, as the frame's pose sees it.
fn fd_jacobian(
    model: &Model,
    data: &mut Data,
    q: &[f64],
    frame: FrameId,
    reference: Reference,
) -> DMatrix<f64> {
    let eps = 1e-6;
    let nv = model.nv();
    let mut j = DMatrix::zeros(6, nv);
    forward_kinematics(model, data, q);
    let x0 = frame_se3(model, data, frame);
    for k in 0..nv {
        let mut e = vec![0.0; nv];
        e[k] = 1.0;
        forward_kinematics(model, data, &axpy(q, eps, &e));
        let xp = frame_se3(model, data, frame);
        forward_kinematics(model, data, &axpy(q, -eps, &e));
        let xm = frame_se3(model, data, frame);
        let dp = (xp.trans - xm.trans) / (2.0 * eps);
        let (lin, ang) = match reference {
            Reference::Base => (dp, log3(&(xp.rot * xm.rot.transpose())) / (2.0 * eps)),
            Reference::Local => (
                x0.rot.transpose() * dp,
                log3(&(xm.rot.transpose() * xp.rot)) / (2.0 * eps),
            ),
        };
        for r in 0..3 {
            j[(r, k)] = lin[r];
            j[(r + 3, k)] = ang[r];
        }
    }
    j
}

#[test]
fn jacobian_matches_finite_differences_of_forward_kinematics() {
    for (name, model) in robots() {
        let nv = model.nv();
        let mut data = model.create_data();
        let mut rng = test_support::rng(5);
        let mut jac = Matrix6xX::zeros(nv);
        for _ in 0..40 {
            let q = common::random_config(&mut rng, &model);
            for frame in 0..model.frames.len() {
                for reference in [Reference::Base, Reference::Local] {
                    let fd = fd_jacobian(&model, &mut data, &q, frame, reference);
                    forward_kinematics(&model, &mut data, &q);
                    frame_jacobian(&model, &data, frame, reference, &mut jac);
                    let err = (DMatrix::from_iterator(6, nv, jac.iter().copied()) - fd).amax();
                    assert!(
                        err < 1e-7,
                        "{name}: frame {} {reference:?} Jacobian off by {err}",
                        model.frames[frame].name
                    );
                }
            }
        }
    }
}

#[test]
fn jdot_v_matches_finite_differences_of_jacobian() {
    let eps = 1e-6;
    for (name, model) in robots() {
        let nv = model.nv();
        let mut data = model.create_data();
        let mut rng = test_support::rng(6);
        let mut jp = Matrix6xX::zeros(nv);
        let mut jm = Matrix6xX::zeros(nv);
        for _ in 0..60 {
            let q = common::random_config(&mut rng, &model);
            let v = rng.uniform_vec(nv, -2.0, 2.0);
            let frame = rng.random_range(0..model.frames.len());
            for reference in [Reference::Base, Reference::Local] {
                forward_kinematics(&model, &mut data, &axpy(&q, eps, &v));
                frame_jacobian(&model, &data, frame, reference, &mut jp);
                forward_kinematics(&model, &mut data, &axpy(&q, -eps, &v));
                frame_jacobian(&model, &data, frame, reference, &mut jm);
                let fd = (&jp - &jm) / (2.0 * eps) * dv(&v);
                let got = frame_jdot_v(&model, &mut data, &q, &v, frame, reference).to_vector();
                let err = (got - fd).amax();
                assert!(err < 1e-6, "{name}: {reference:?} Jdot v off by {err}");
            }
        }
    }
}

#[test]
fn frame_velocity_and_acceleration_match_jacobian() {
    for (name, model) in robots() {
        let nv = model.nv();
        let mut data = model.create_data();
        let mut rng = test_support::rng(7);
        let mut jac = Matrix6xX::zeros(nv);
        for _ in 0..60 {
            let q = common::random_config(&mut rng, &model);
            let v = rng.uniform_vec(nv, -2.0, 2.0);
            let a = rng.uniform_vec(nv, -3.0, 3.0);
            let frame = rng.random_range(0..model.frames.len());
            for reference in [Reference::Base, Reference::Local] {
                let jdv = frame_jdot_v(&model, &mut data, &q, &v, frame, reference).to_vector();
                forward_kinematics_second_order(&model, &mut data, &q, &v, Some(&a));
                frame_jacobian(&model, &data, frame, reference, &mut jac);
                let vel = frame_velocity(&model, &data, frame, reference).to_vector();
                assert!((vel - &jac * dv(&v)).amax() < 1e-10, "{name}: v != J v");
                let acc = frame_acceleration(&model, &data, frame, reference).to_vector();
                assert!(
                    (acc - (&jac * dv(&a) + jdv)).amax() < 1e-9,
                    "{name}: a != J a + Jdot v"
                );
            }
        }
    }
}

#[test]
fn energies_match_mass_matrix_and_gravity() {
    let eps = 1e-6;
    for (name, model) in robots() {
        let nv = model.nv();
        let mut data = model.create_data();
        let mut rng = test_support::rng(8);
        for _ in 0..50 {
            let q = common::random_config(&mut rng, &model);
            let v = rng.uniform_vec(nv, -2.0, 2.0);
            let m = crba(&model, &mut data, &q).clone();
            let ke = kinetic_energy(&model, &mut data, &q, &v);
            assert!(
                (ke - 0.5 * dv(&v).dot(&(&m * dv(&v)))).abs() < 1e-10,
                "{name}: KE != 1/2 vT M v"
            );
            // g(q) is the gradient of the potential energy.
            let g = gravity(&model, &mut data, &q).clone();
            let dvdt = (potential_energy(&model, &mut data, &axpy(&q, eps, &v))
                - potential_energy(&model, &mut data, &axpy(&q, -eps, &v)))
                / (2.0 * eps);
            assert!((dvdt - g.dot(&dv(&v))).abs() < 1e-6, "{name}: dV/dt != g.v");
        }
    }
}

/// Passive motion (τ = 0, no damping) from a random state, integrated with
/// RK4 at a small step: total energy must stay constant.
#[test]
fn passive_simulation_conserves_energy() {
    let dt = 2e-4;
    let steps = 5000; // one second
    for (name, model) in robots() {
        let nv = model.nv();
        let mut data = model.create_data();
        let mut rng = test_support::rng(9);
        let tau = vec![0.0; nv];
        let mut q = common::random_config(&mut rng, &model);
        let mut v = rng.uniform_vec(nv, -1.0, 1.0);
        let energy = |data: &mut Data, q: &[f64], v: &[f64]| {
            kinetic_energy(&model, data, q, v) + potential_energy(&model, data, q)
        };
        let e0 = energy(&mut data, &q, &v);
        let accel = |data: &mut Data, q: &[f64], v: &[f64]| -> Vec<f64> {
            forward_dynamics(&model, data, q, v, &tau)
                .unwrap()
                .iter()
                .copied()
                .collect()
        };
        let mut max_drift: f64 = 0.0;
        for _ in 0..steps {
            let k1v = accel(&mut data, &q, &v);
            let k1q = v.clone();
            let q2 = axpy(&q, dt / 2.0, &k1q);
            let v2 = axpy(&v, dt / 2.0, &k1v);
            let k2v = accel(&mut data, &q2, &v2);
            let q3 = axpy(&q, dt / 2.0, &v2);
            let v3 = axpy(&v, dt / 2.0, &k2v);
            let k3v = accel(&mut data, &q3, &v3);
            let q4 = axpy(&q, dt, &v3);
            let v4 = axpy(&v, dt, &k3v);
            let k4v = accel(&mut data, &q4, &v4);
            for i in 0..nv {
                q[i] += dt / 6.0 * (k1q[i] + 2.0 * v2[i] + 2.0 * v3[i] + v4[i]);
                v[i] += dt / 6.0 * (k1v[i] + 2.0 * k2v[i] + 2.0 * k3v[i] + k4v[i]);
            }
            max_drift = max_drift.max((energy(&mut data, &q, &v) - e0).abs());
        }
        // The robots swing through tens of joules; RK4's error at this step is
        // far below a microjoule unless the dynamics are inconsistent.
        assert!(
            max_drift < 1e-6,
            "{name}: energy drifted by {max_drift} J (E0 = {e0} J)"
        );
        assert!(
            v.iter().any(|x| x.abs() > 0.1),
            "{name}: the robot did not move"
        );
    }
}

#[test]
fn point_mass_pendulum_has_textbook_dynamics() {
    let urdf = r#"<robot name="p"><link name="base"/>
      <link name="bob"><inertial><origin xyz="0 0 -0.8"/><mass value="2"/>
        <inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>
      <joint name="pivot" type="continuous"><parent link="base"/><child link="bob"/><axis xyz="0 1 0"/></joint>
      </robot>"#;
    let model = Model::from_urdf_str(urdf, &LoadOptions::default()).unwrap();
    let mut data = model.create_data();
    let (m, l, g) = (2.0, 0.8, 9.81);
    for theta in [-1.0, 0.0, 0.4, 2.0] {
        assert!((crba(&model, &mut data, &[theta])[(0, 0)] - m * l * l).abs() < 1e-12);
        // Rotating by +θ about y swings the bob towards -x... its torque is m g l sin θ.
        let tau = gravity(&model, &mut data, &[theta])[0];
        assert!(
            (tau - m * g * l * f64::sin(theta)).abs() < 1e-12,
            "θ={theta}: {tau}"
        );
    }
}
