//! Times FK, Jacobian, mass matrix, inverse and forward dynamics of the Panda
//! with dynibo, with the protocol of bench-anchors/README.md: a pool of 256
//! states, batches of 1000 calls, the median per call over 300 batches.

use std::hint::black_box;
use std::time::Instant;

fn median_ns(mut f: impl FnMut()) -> f64 {
    for _ in 0..20_000 {
        f();
    }
    let mut per_call: Vec<f64> = (0..300)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..1000 {
                f();
            }
            t.elapsed().as_nanos() as f64 / 1000.0
        })
        .collect();
    per_call.sort_by(|a, b| a.partial_cmp(b).unwrap());
    per_call[per_call.len() / 2]
}

fn main() {
    let urdf = std::env::args().nth(1).expect("usage: dynibo-anchor PANDA_URDF");
    let mut robot = dynibo::Robot::from_urdf(&urdf).expect("load URDF");
    let n = robot.generalized_count();
    let tip = robot.link_id("peg_tip").expect("peg_tip link");
    let mut s: u64 = 7;
    let mut next = move || {
        s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = s;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    };
    let pool: Vec<[Vec<f64>; 3]> = (0..256)
        .map(|_| {
            let q = (0..n)
                .map(|i| {
                    let (lo, hi) = (robot.joint_lower_limit(i).unwrap(), robot.joint_upper_limit(i).unwrap());
                    lo + (hi - lo) * next()
                })
                .collect();
            let v = (0..n).map(|_| 2.0 * next() - 1.0).collect();
            let a = (0..n).map(|_| 2.0 * next() - 1.0).collect();
            [q, v, a]
        })
        .collect();
    let mut jac = vec![0.0; 6 * n];
    let mut mass = vec![0.0; n * n];
    let mut out = vec![0.0; n];
    let mut k = 0usize;
    let mut state = || {
        k = (k + 1) % pool.len();
        k
    };
    let fk = median_ns(|| {
        black_box(robot.forward_kinematics(&pool[state()][0], tip).unwrap());
    });
    let jacobian = median_ns(|| {
        robot.jacobian(&pool[state()][0], tip, &mut jac).unwrap();
        black_box(&jac);
    });
    let crba = median_ns(|| {
        robot.mass_matrix(&pool[state()][0], &mut mass).unwrap();
        black_box(&mass);
    });
    let rnea = median_ns(|| {
        let s = &pool[state()];
        robot.inverse_dynamics(&s[0], &s[1], &s[2], &[], &mut out).unwrap();
        black_box(&out);
    });
    let fd = median_ns(|| {
        let s = &pool[state()];
        robot.forward_dynamics(&s[0], &s[1], &s[2], &[], &mut out).unwrap();
        black_box(&out);
    });
    println!("dynibo 0.5.3 (median ns/call): fk {fk:.0}  fk+jacobian {jacobian:.0}  crba {crba:.0}  rnea {rnea:.0}  forward_dynamics(aba) {fd:.0}");
}
