//! One full control step (kinematics, dynamics, OSC, QP filter) for the
//! Panda, unsaturated (the filter passes the OSC torques through) and
//! saturated (the QP solves every cycle). Criterion gives the medians; a
//! second pass times 20 000 single steps for the tail percentiles, which
//! criterion's batched samples cannot show. `control_cycle/unsaturated` is
//! the same step through `ControlCycle::cycle`, as the daemon and the fast
//! path run it: the hardware-state message unpacked, the torque command and
//! the sensor frame packed.
//!
//! `cargo bench -p rt-controller --bench control_step`

use criterion::Criterion;
use nalgebra::Vector3;
use robot_model::Model;
use rt_controller::{
    ControlCycle, Controller, ControllerConfig, ControllerData, QpOutcome, RobotState, step,
};
use shared_mem_schema::{HardwareState, Message, SensorFrame, TorqueCommand};
use std::hint::black_box;
use std::time::Instant;

use robot_model::descriptions::PANDA_READY_Q as READY;

struct Case {
    model: Model,
    ctrl: Controller,
    data: ControllerData,
    q: [f64; 7],
    v: [f64; 7],
    t: f64,
}

impl Case {
    fn new(saturated: bool) -> Self {
        let model = robot_model::descriptions::builtin("panda").unwrap();
        let ctrl = Controller::new(&model, ControllerConfig::default()).unwrap();
        let data = ctrl.create_data(&model);
        // Moving slowly, so that Coriolis terms and J̇v are not zero.
        let v = [0.005, -0.01, 0.008, 0.01, -0.02, 0.015, 0.03];
        let mut c = Case {
            model,
            ctrl,
            data,
            q: READY,
            v,
            t: 0.0,
        };
        c.cycle();
        if saturated {
            // A target 30 cm away: OSC asks for hundreds of newtons.
            let (p, r) = (c.data.ee.pos, c.data.ee.rot);
            c.data
                .trajectory
                .reset(&(p + Vector3::new(0.3, 0.2, -0.3)), &r, c.t);
        }
        let info = c.cycle();
        let solved = matches!(info.qp, Some(QpOutcome::Solved { .. }));
        assert_eq!(solved, saturated, "{info:?}");
        c
    }

    fn cycle(&mut self) -> rt_controller::StepInfo {
        self.t += 0.001;
        let s = RobotState {
            q: &self.q,
            v: &self.v,
            tau_measured: None,
            wrench: None,
        };
        step(&self.model, &self.ctrl, &mut self.data, &s, None, self.t)
    }
}

fn percentiles(name: &str, saturated: bool) {
    let mut c = Case::new(saturated);
    let n = 20_000;
    let mut ns = Vec::with_capacity(n);
    for _ in 0..1000 {
        black_box(c.cycle());
    }
    for _ in 0..n {
        let t0 = Instant::now();
        black_box(c.cycle());
        ns.push(t0.elapsed().as_nanos() as f64);
    }
    ns.sort_by(f64::total_cmp);
    let p = |x: f64| ns[((n - 1) as f64 * x) as usize] / 1000.0;
    println!(
        "{name}: single-step µs  p50 {:.2}  p99 {:.2}  p99.9 {:.2}  max {:.2}  (n = {n})",
        p(0.5),
        p(0.99),
        p(0.999),
        ns[n - 1] / 1000.0
    );
}

fn main() {
    let mut crit = Criterion::default().configure_from_args();
    for (name, saturated) in [
        ("control_step/unsaturated", false),
        ("control_step/saturated", true),
    ] {
        let mut c = Case::new(saturated);
        crit.bench_function(name, |b| b.iter(|| black_box(c.cycle())));
    }
    {
        let model = robot_model::descriptions::builtin("panda").unwrap();
        let mut cycle = ControlCycle::new(&model, ControllerConfig::default()).unwrap();
        let mut state = HardwareState::empty(7);
        state.q[..7].copy_from_slice(&READY);
        state.v[..7].copy_from_slice(&[0.005, -0.01, 0.008, 0.01, -0.02, 0.015, 0.03]);
        let mut cmd = TorqueCommand::empty(7);
        let mut frame = *SensorFrame::boxed_zeroed();
        crit.bench_function("control_cycle/unsaturated", |b| {
            b.iter(|| {
                state.step += 1;
                state.header.t_hw_ns += 1_000_000;
                black_box(cycle.cycle(&model, &state, None, 0, &mut cmd, &mut frame))
            })
        });
    }
    crit.final_summary();
    // Criterion's --list / --test runs must not do the timing pass.
    if std::env::args().any(|a| a == "--bench") {
        percentiles("unsaturated", false);
        percentiles("saturated", true);
    }
}
