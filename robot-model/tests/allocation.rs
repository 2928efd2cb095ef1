//! After `Data` is made, no algorithm allocates: a counting global allocator
//! watches thousands of calls of every algorithm.

mod common;

use nalgebra::Matrix6xX;
use robot_model::*;
use test_support::Uniform;
use test_support::alloc::{Counting, count};

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn algorithms_do_not_allocate() {
    for (name, model) in common::robots() {
        let nv = model.nv();
        let mut data = model.create_data();
        let mut rng = test_support::rng(11);
        // Inputs and outputs are made before counting starts.
        let states: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> = (0..64)
            .map(|_| {
                (
                    common::random_config(&mut rng, &model),
                    rng.uniform_vec(nv, -1.0, 1.0),
                    rng.uniform_vec(nv, -1.0, 1.0),
                )
            })
            .collect();
        let mut jac = Matrix6xX::zeros(nv);
        let frame = model
            .frame_id("peg_tip")
            .or_else(|_| model.frame_id("fr3_hand_tcp"))
            .or_else(|_| model.frame_id("hand"))
            .unwrap();
        let mut checksum = 0.0;

        let n = count(|| {
            for i in 0..5000 {
                let (q, v, a) = &states[i % states.len()];
                forward_kinematics(&model, &mut data, q);
                let x = frame_se3(&model, &data, frame);
                frame_jacobian(&model, &data, frame, Reference::Base, &mut jac);
                frame_jacobian(&model, &data, frame, Reference::Local, &mut jac);
                let jdv = frame_jdot_v(&model, &mut data, q, v, frame, Reference::Base);
                forward_kinematics_second_order(&model, &mut data, q, v, Some(a));
                let fv = frame_velocity(&model, &data, frame, Reference::Local);
                let fa = frame_acceleration(&model, &data, frame, Reference::Base);
                crba(&model, &mut data, q);
                gravity(&model, &mut data, q);
                nonlinear_effects(&model, &mut data, q, v);
                let tau_sum = rnea(&model, &mut data, q, v, a).sum();
                let ddq_sum = forward_dynamics(&model, &mut data, q, v, a).unwrap().sum();
                coriolis_matrix(&model, &mut data, q, v);
                let e = kinetic_energy(&model, &mut data, q, v)
                    + potential_energy(&model, &mut data, q);
                let com = center_of_mass(&model, &data);
                checksum +=
                    x.trans.x + jdv.lin.x + fv.ang.y + fa.lin.z + tau_sum + ddq_sum + e + com.z;
            }
        })
        .allocations;
        assert!(checksum.is_finite());
        assert_eq!(
            n, 0,
            "{name}: {n} allocations in 5000 cycles of every algorithm"
        );
    }
}

/// The counter does count: a deliberate allocation is seen.
#[test]
fn counter_sees_allocations() {
    let mut v = Vec::new();
    let c = count(|| v = std::hint::black_box(vec![1u64, 2, 3]));
    assert_eq!(v.len(), 3);
    assert!(c.allocations >= 1);
    let c = count(|| drop(std::mem::take(&mut v)));
    assert_eq!((c.allocations, c.frees), (0, 1));
}
