//! Criterion benchmarks of the core algorithms on the Panda, over a pool of
//! random states (the same protocol as the anchors in bench-anchors/).
//! Run: `cargo bench -p robot-model --bench dynamics`; medians go into
//! docs/performance.md.

use criterion::{Criterion, criterion_group, criterion_main};
use nalgebra::Matrix6xX;
use robot_model::*;
use std::hint::black_box;
use std::time::Duration;
use test_support::Uniform;

const POOL: usize = 256;

/// Deterministic states within the joint limits.
fn states(model: &Model) -> Vec<[Vec<f64>; 3]> {
    let mut rng = test_support::rng(7);
    let mut next = move || rng.uniform(0.0, 1.0);
    (0..POOL)
        .map(|_| {
            let q = model.joints[1..]
                .iter()
                .map(|j| j.limits.lower + (j.limits.upper - j.limits.lower) * next())
                .collect();
            let v = (0..model.nv()).map(|_| 2.0 * next() - 1.0).collect();
            let a = (0..model.nv()).map(|_| 2.0 * next() - 1.0).collect();
            [q, v, a]
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/urdf/panda.urdf");
    let model = Model::from_urdf_file(path, &LoadOptions::default()).unwrap();
    let mut data = model.create_data();
    let pool = states(&model);
    let frame = model.frame_id("peg_tip").unwrap();
    let mut jac = Matrix6xX::zeros(model.nv());
    let mut g = c.benchmark_group("panda");
    let mut i = 0usize;
    let mut next = || {
        i = (i + 1) % POOL;
        &pool[i]
    };
    g.bench_function("fk", |b| {
        b.iter(|| forward_kinematics(&model, &mut data, black_box(&next()[0])))
    });
    g.bench_function("fk+jacobian", |b| {
        b.iter(|| {
            forward_kinematics(&model, &mut data, black_box(&next()[0]));
            frame_jacobian(&model, &data, frame, Reference::Base, &mut jac);
            black_box(&jac);
        })
    });
    g.bench_function("jdot_v", |b| {
        b.iter(|| {
            let s = next();
            black_box(frame_jdot_v(
                &model,
                &mut data,
                &s[0],
                &s[1],
                frame,
                Reference::Base,
            ))
        })
    });
    g.bench_function("crba", |b| {
        b.iter(|| {
            black_box(crba(&model, &mut data, black_box(&next()[0])));
        })
    });
    g.bench_function("rnea", |b| {
        b.iter(|| {
            let s = next();
            black_box(rnea(&model, &mut data, &s[0], &s[1], &s[2]));
        })
    });
    g.bench_function("gravity", |b| {
        b.iter(|| {
            black_box(gravity(&model, &mut data, black_box(&next()[0])));
        })
    });
    g.bench_function("forward_dynamics", |b| {
        b.iter(|| {
            let s = next();
            black_box(forward_dynamics(&model, &mut data, &s[0], &s[1], &s[2]).unwrap());
        })
    });
    g.bench_function("coriolis_matrix", |b| {
        b.iter(|| {
            let s = next();
            black_box(coriolis_matrix(&model, &mut data, &s[0], &s[1]));
        })
    });
    g.finish();
}

criterion_group! {
    name = benches;
    config = Criterion::default()
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(3))
        .sample_size(60);
    targets = bench
}
criterion_main!(benches);
