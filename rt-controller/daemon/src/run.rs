//! The 1 kHz loop around [`Daemon::cycle`]: start-up, the clock (wall or
//! hardware), overrun accounting and the shutdown hold.

use crate::backend::{Hardware, HardwareError};
use crate::config::Clock;
use crate::control::Daemon;
use crate::rt::pause_briefly;
use crate::rt_alloc;
use crate::stats::RunSummary;
use shared_mem_schema::process::mono_now_ns;
use std::sync::atomic::Ordering;

impl<H: Hardware> Daemon<H> {
    /// Runs the loop until `stop()` returns true; then holds for
    /// `timing.shutdown_hold_s`, ends the hardware's session
    /// ([`Hardware::finish`]) and returns. `on_ready` runs once the first
    /// hardware state is in (systemd's READY). A robot error
    /// ([`HardwareError::Robot`]) is latched as the daemon's Fault and
    /// published in a last status before it is returned.
    pub fn run(
        &mut self,
        stop: impl FnMut() -> bool,
        on_ready: impl FnOnce(),
    ) -> Result<RunSummary, HardwareError> {
        let result = self.run_loop(stop, on_ready);
        rt_alloc::leave_realtime();
        match result {
            Ok(summary) => {
                let finished = self.hw.finish().map(|()| summary);
                if let Err(HardwareError::Robot { code, .. }) = &finished {
                    self.latch_robot_fault(*code, mono_now_ns());
                }
                finished
            }
            Err(e) => {
                // The Fault is published first; then the hardware still
                // ends what it can (the Franka's motion, when the robot has
                // not ended it itself, e.g. after an external sensor's
                // fault). The first error is the one reported.
                if let HardwareError::Robot { code, .. } = &e {
                    self.latch_robot_fault(*code, mono_now_ns());
                }
                let _ = self.hw.finish();
                Err(e)
            }
        }
    }

    fn run_loop(
        &mut self,
        mut stop: impl FnMut() -> bool,
        on_ready: impl FnOnce(),
    ) -> Result<RunSummary, HardwareError> {
        let timing = self.cfg.timing.clone();
        let period_ns = (self.cfg.controller.period_s * 1e9).round() as u64;
        // Start-up: wait for the hardware (not real-time yet).
        let start = mono_now_ns();
        loop {
            let now = mono_now_ns();
            if self.poll_hardware(now)? {
                break;
            }
            if stop() {
                return Ok(RunSummary::default());
            }
            if now - start > (timing.startup_timeout_s * 1e9) as u64 {
                return Err(HardwareError::NoStartupState {
                    backend: self.hw.name(),
                    timeout_s: timing.startup_timeout_s,
                    namespace: self.cfg.backend.namespace.clone(),
                });
            }
            std::thread::sleep(std::time::Duration::from_micros(500));
        }
        on_ready();
        // From here on the loop's small allocations (iceoryx2's, clarabel's)
        // come from the real-time pools when the binary installs
        // `rt_alloc::RtAllocator`.
        rt_alloc::enter_realtime();
        let mut stopping_until: Option<u64> = None;
        let mut deadline = mono_now_ns();
        let mut fresh = true; // the state of the start-up poll
        loop {
            if stopping_until.is_none() && stop() {
                self.request_hold();
                stopping_until = Some(mono_now_ns() + (timing.shutdown_hold_s * 1e9) as u64);
            }
            if let Some(until) = stopping_until
                && mono_now_ns() >= until
            {
                break;
            }
            let woke = match timing.clock {
                Clock::Wall => {
                    shared_mem_schema::process::sleep_until_ns(deadline);
                    let now = mono_now_ns();
                    self.stats.wakeup.record(now.saturating_sub(deadline));
                    fresh |= self.poll_hardware(now)?;
                    now
                }
                Clock::Hardware => {
                    let wait_start = mono_now_ns();
                    let mut spins = 0u32;
                    let mut now = wait_start;
                    while !fresh {
                        let polled = mono_now_ns();
                        fresh = self.poll_hardware(polled)?;
                        // Compute time counts from the state's arrival: a
                        // hardware that clocks the loop (the Franka) waits
                        // for its next state inside the poll.
                        now = if fresh { mono_now_ns() } else { polled };
                        // Stop waiting on a stop request, or when the
                        // shutdown hold is over; keep waiting during it.
                        let stopping = match stopping_until {
                            Some(until) => now >= until,
                            None => stop(),
                        };
                        if fresh
                            || now - wait_start > (timing.hardware_timeout_ms * 1e6) as u64
                            || stopping
                        {
                            break;
                        }
                        spins += 1;
                        if spins > 200 {
                            pause_briefly();
                        }
                    }
                    now
                }
            };
            self.cycle(woke, fresh)?;
            fresh = false;
            let done = mono_now_ns();
            self.stats.compute.record(done.saturating_sub(woke));
            if timing.clock == Clock::Wall {
                deadline += period_ns;
                if done > deadline {
                    self.stats.overruns += 1;
                    self.shared
                        .overruns
                        .store(self.stats.overruns, Ordering::Relaxed);
                    if done > deadline + 10 * period_ns {
                        // A long stall: restart the schedule rather than
                        // running the missed cycles back to back.
                        deadline = done;
                    }
                }
            }
        }
        rt_alloc::leave_realtime();
        let now = mono_now_ns();
        self.publish_status(now);
        Ok(RunSummary {
            cycles: self.stats.cycles,
            overruns: self.stats.overruns,
        })
    }
}
