//! The daemon's TOML configuration: robot, control law, backend, timing and
//! real-time settings. Every field is documented and defaulted; unknown
//! fields are errors and bad values name their dotted field.

use rt_controller::{ControllerConfig, SpeedLimitSource};
use serde::{Deserialize, Serialize};
use shared_mem_schema::config::{
    ConfigFileError, FieldError, at_least, ensure, non_negative, parse_toml, positive, read_toml,
    within,
};
use std::path::Path;

/// A daemon configuration the daemon cannot run with.
#[derive(Debug, thiserror::Error)]
pub enum DaemonConfigError {
    /// The file could not be read, or its TOML is malformed, has an unknown
    /// field or a wrong type.
    #[error(transparent)]
    File(#[from] ConfigFileError),
    /// A value is out of range (its message is the whole story: no
    /// source, so that a chain of errors does not print it twice).
    #[error("configuration: {0}")]
    BadValue(FieldError),
}

impl From<FieldError> for DaemonConfigError {
    fn from(e: FieldError) -> Self {
        Self::BadValue(e)
    }
}

/// What drives the loop's cycles.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Clock {
    /// Absolute 1 kHz deadlines on `CLOCK_MONOTONIC` (deployment).
    Wall,
    /// One cycle per new hardware state (a lockstep simulator, or a robot
    /// whose driver calls back at its own rate).
    Hardware,
}

/// Which hardware the daemon drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum BackendKind {
    /// hw-sim over shared memory.
    Sim,
    /// A Franka robot (FR3 or Panda/FER) over the Franka Control Interface
    /// (docs/franka.md); settings in `[backend.franka]`.
    Franka,
}

/// Which Franka robot: it picks the FCI protocol version.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FrankaGeneration {
    /// Franka Research 3 (FCI protocol version 10).
    Fr3,
    /// Franka Emika Robot, "Panda" (FCI protocol version 5). Not run
    /// against anything yet: franky-sim simulates an FR3 only.
    Panda,
}

/// Where the sensor frame's wrench comes from on a Franka.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WrenchSource {
    /// The robot's estimate from its joint torques (`K_F_ext_hat_K`),
    /// turned into the flange frame.
    RobotEstimate,
    /// None: the wrench reads zero (the force supervision then sees none).
    None,
    /// An external ATI Net F/T on the wrist (`[backend.franka.net_ft]`),
    /// in the sensor's frame (crate::netft).
    NetFt,
}

/// An ATI Net F/T streaming over RDT (`wrench = "net_ft"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NetFtConfig {
    /// The sensor's address, a host name or IP, optionally `:port` (the RDT
    /// port, 49152, by default).
    pub address: String,
    /// Counts per newton of the sensor's calibration (its web page, or
    /// `netftapi2.xml`).
    pub counts_per_force: f64,
    /// Counts per newton-metre of the sensor's calibration.
    pub counts_per_torque: f64,
    /// A sensor silent for longer than this is a Fault, ms.
    pub timeout_ms: f64,
    /// How long the start-up waits for the sensor's first record, s.
    pub start_timeout_s: f64,
    /// How long start-up averages the sensor at rest, ms, as the bias the
    /// loop's readings are taken relative to (tare; 0: the sensor's raw
    /// values, bias and tool weight in).
    pub tare_ms: f64,
}

impl Default for NetFtConfig {
    fn default() -> Self {
        // ATI's factory address and the counts of its common calibrations
        // (check them against the sensor's own: they differ by calibration).
        Self {
            address: "192.168.1.1".into(),
            counts_per_force: 1_000_000.0,
            counts_per_torque: 1_000_000.0,
            timeout_ms: 10.0,
            start_timeout_s: 2.0,
            tare_ms: 100.0,
        }
    }
}

/// A host name or IP address, optionally with `:port`, of the device at
/// `field`.
fn network_address(field: &str, address: &str) -> Result<(), FieldError> {
    ensure(
        !address.is_empty() && !address.contains(char::is_whitespace),
        field,
        format_args!("{address:?}"),
        "must be a host name or IP address, optionally with :port",
    )
}

impl NetFtConfig {
    fn validate(&self) -> Result<(), FieldError> {
        network_address("backend.franka.net_ft.address", &self.address)?;
        positive(
            "backend.franka.net_ft.counts_per_force",
            self.counts_per_force,
        )?;
        positive(
            "backend.franka.net_ft.counts_per_torque",
            self.counts_per_torque,
        )?;
        positive("backend.franka.net_ft.timeout_ms", self.timeout_ms)?;
        positive(
            "backend.franka.net_ft.start_timeout_s",
            self.start_timeout_s,
        )?;
        // Bounded: a longer silence no longer protects the arm, and huge
        // values overflow the time conversions.
        within(
            "backend.franka.net_ft.timeout_ms",
            self.timeout_ms,
            0.0..=5000.0,
        )?;
        within(
            "backend.franka.net_ft.start_timeout_s",
            self.start_timeout_s,
            0.0..=60.0,
        )?;
        within("backend.franka.net_ft.tare_ms", self.tare_ms, 0.0..=2000.0)
    }
}

/// The Franka backend (`backend.kind = "franka"`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FrankaConfig {
    /// The robot's FCI address: a host name or IP, optionally `:port`
    /// (the FCI command port, 1337, by default).
    pub address: String,
    /// `fr3` or `panda`.
    pub generation: FrankaGeneration,
    /// Joint torques above which the robot reports a contact, N·m (the
    /// robot's `lower_torque_thresholds`).
    pub contact_torque_nm: [f64; 7],
    /// Joint torques above which the robot stops in a collision reflex,
    /// N·m (`upper_torque_thresholds`).
    pub collision_torque_nm: [f64; 7],
    /// Cartesian forces (N) and moments (N·m) above which the robot reports
    /// a contact (`lower_force_thresholds`).
    pub contact_force: [f64; 6],
    /// Cartesian forces and moments above which the robot stops in a
    /// collision reflex (`upper_force_thresholds`).
    pub collision_force: [f64; 6],
    /// Apply the client library's torque-rate limiter (1000 N·m/s on the
    /// commanded torque without gravity, against the robot's last
    /// commanded torque) before sending. On by default: it is the robot's
    /// own constraint, and the control law limits the rate of the torque
    /// *with* gravity, whose gravity part the robot adds itself.
    pub rate_limit: bool,
    /// Cut-off of the client library's first-order low-pass filter on the
    /// commanded torques, Hz; 1000 (the default) turns it off: the control
    /// law's torques are already rate-limited, and the filter's lag would
    /// only take phase margin from the impedance's damping.
    pub cutoff_hz: f64,
    /// `robot_estimate`, `net_ft` or `none`.
    pub wrench: WrenchSource,
    /// The external sensor of `wrench = "net_ft"`.
    pub net_ft: NetFtConfig,
}

impl Default for FrankaConfig {
    fn default() -> Self {
        // The thresholds of libfranka's examples (`setDefaultBehavior`).
        Self {
            address: "172.16.0.2".into(),
            generation: FrankaGeneration::Fr3,
            contact_torque_nm: [20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0],
            collision_torque_nm: [20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0],
            contact_force: [20.0, 20.0, 20.0, 25.0, 25.0, 25.0],
            collision_force: [20.0, 20.0, 20.0, 25.0, 25.0, 25.0],
            rate_limit: true,
            cutoff_hz: 1000.0,
            wrench: WrenchSource::RobotEstimate,
            net_ft: NetFtConfig::default(),
        }
    }
}

impl FrankaConfig {
    fn validate(&self) -> Result<(), FieldError> {
        network_address("backend.franka.address", &self.address)?;
        // On a robot nothing turns a protection off.
        ensure(
            self.rate_limit,
            "backend.franka.rate_limit",
            false,
            "must be true on a robot (the robot's own torque-rate limit)",
        )?;
        ensure(
            self.wrench != WrenchSource::None,
            "backend.franka.wrench",
            "\"none\"",
            "must be \"robot_estimate\" or \"net_ft\" on a robot (\"none\" turns the force \
             supervision off)",
        )?;
        within("backend.franka.cutoff_hz", self.cutoff_hz, 0.0..=1000.0)?;
        positive("backend.franka.cutoff_hz", self.cutoff_hz)?;
        for (field, lower, upper) in [
            (
                "backend.franka.collision_torque_nm",
                &self.contact_torque_nm[..],
                &self.collision_torque_nm[..],
            ),
            (
                "backend.franka.collision_force",
                &self.contact_force[..],
                &self.collision_force[..],
            ),
        ] {
            for (i, (&lo, &hi)) in lower.iter().zip(upper).enumerate() {
                positive(field, lo)?;
                positive(field, hi)?;
                ensure(
                    lo <= hi,
                    field,
                    format_args!("{hi} (entry {i})"),
                    "must be at least the contact threshold of the same entry",
                )?;
            }
        }
        if self.wrench == WrenchSource::NetFt {
            self.net_ft.validate()?;
        }
        Ok(())
    }
}

/// The hardware backend.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BackendConfig {
    /// `sim` or `franka`.
    pub kind: BackendKind,
    /// Service namespace shared with the simulator and the learner.
    pub namespace: String,
    /// The Franka backend's settings (used when `kind = "franka"`).
    pub franka: FrankaConfig,
}

impl Default for BackendConfig {
    fn default() -> Self {
        Self {
            kind: BackendKind::Sim,
            namespace: shared_mem_schema::DEFAULT_NAMESPACE.into(),
            franka: FrankaConfig::default(),
        }
    }
}

/// Rates, timeouts and the loop's clock.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct TimingConfig {
    /// `wall` (deadlines) or `hardware` (driven by new states).
    pub clock: Clock,
    /// Hardware silent this long → Fault, no further torques, ms.
    pub hardware_timeout_ms: f64,
    /// How long to wait for the first hardware state at start, s.
    pub startup_timeout_s: f64,
    /// Status publication period, ms (~10 Hz).
    pub status_period_ms: f64,
    /// Lockstep only: at every `action_period_steps`-th hardware step the
    /// loop waits for the action addressed to that step (deterministic runs
    /// with the learner in the loop). Off in deployment: the controller
    /// never waits for the learner.
    pub lockstep_actions: bool,
    /// Hardware steps per policy action (50 at 1 kHz = 20 Hz). Also the
    /// speed bound's period: an action's step is cut to its share of the
    /// largest for the steps since the last applied action (`admission.rs`).
    pub action_period_steps: u64,
    /// An action is applied at most once per this many hardware steps (at
    /// most `action_period_steps`); a sooner one waits at the queue's front
    /// (half a policy period: a 20 Hz policy's jitter never waits, a
    /// flooding peer gets at most 40 Hz).
    pub min_action_interval_steps: u64,
    /// Lockstep only: how long to wait for an addressed action, s.
    pub lockstep_action_timeout_s: f64,
    /// On SIGTERM/SIGINT: hold the pose this long before exiting, s.
    pub shutdown_hold_s: f64,
    /// An action is dropped as stale when the observation it answers (its
    /// `header.t_hw_ns`, a hardware time the daemon itself published) is
    /// older than this on the hardware's clock when it would be applied,
    /// ms (two policy periods).
    pub max_action_age_ms: f64,
}

impl Default for TimingConfig {
    fn default() -> Self {
        Self {
            clock: Clock::Wall,
            hardware_timeout_ms: 50.0,
            startup_timeout_s: 10.0,
            status_period_ms: 100.0,
            lockstep_actions: false,
            action_period_steps: shared_mem_schema::rates::ACTION_PERIOD_STEPS,
            min_action_interval_steps: shared_mem_schema::rates::ACTION_PERIOD_STEPS / 2,
            lockstep_action_timeout_s: 5.0,
            shutdown_hold_s: 0.3,
            max_action_age_ms: 2.0 * shared_mem_schema::rates::ACTION_PERIOD_S * 1e3,
        }
    }
}

/// Real-time set-up of the control thread (each step is tried; what the
/// system refuses is reported as a warning, never fatal).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RealtimeConfig {
    /// Try the set-up at all.
    pub enabled: bool,
    /// SCHED_FIFO priority (1–99).
    pub priority: i32,
    /// CPU to pin the control thread to (absent: no pinning).
    pub cpu: Option<usize>,
    /// mlockall(MCL_CURRENT | MCL_FUTURE).
    pub lock_memory: bool,
    /// Stack to pre-fault, KiB.
    pub prefault_stack_kib: usize,
}

impl Default for RealtimeConfig {
    fn default() -> Self {
        Self {
            enabled: true,
            priority: 80,
            cpu: None,
            lock_memory: true,
            prefault_stack_kib: 512,
        }
    }
}

/// The whole daemon configuration.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DaemonConfig {
    /// Robot: a built-in description (`iiwa14`, `panda`) or a URDF path.
    pub robot: String,
    /// The control law.
    pub controller: ControllerConfig,
    /// Hardware backend.
    pub backend: BackendConfig,
    /// Rates and timeouts.
    pub timing: TimingConfig,
    /// Real-time set-up.
    pub realtime: RealtimeConfig,
    /// The fault record ([`crate::fault_record`]): a latched fault, or a
    /// daemon that ended without a clean stop, refuses every later start
    /// until `rt-controller reset`. Required with `backend.kind = "franka"`;
    /// absent, a fault ends with the process (the simulator's runs).
    pub fault_record: Option<std::path::PathBuf>,
}

impl Default for DaemonConfig {
    fn default() -> Self {
        Self {
            robot: "iiwa14".into(),
            controller: ControllerConfig::default(),
            backend: BackendConfig::default(),
            timing: TimingConfig::default(),
            realtime: RealtimeConfig::default(),
            fault_record: None,
        }
    }
}

impl DaemonConfig {
    /// Parses TOML text; `origin` names it in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self, DaemonConfigError> {
        let c: Self = parse_toml(text, Path::new(origin))?;
        c.validate()?;
        Ok(c)
    }

    /// Reads, parses and validates a file.
    pub fn from_file(path: &Path) -> Result<Self, DaemonConfigError> {
        let c: Self = read_toml(path)?;
        c.validate()?;
        Ok(c)
    }

    /// The configuration as TOML (what the daemon prints at start).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot print: {e}\n"))
    }

    /// What a daemon that drives a robot needs beyond [`Self::validate`]
    /// (checked once the command line's overrides are in): a Franka's
    /// faults must survive a restart, so it needs `fault_record`.
    pub fn validate_for_start(&self) -> Result<(), DaemonConfigError> {
        if self.backend.kind == BackendKind::Franka && self.fault_record.is_none() {
            ensure(
                false,
                "fault_record",
                "none",
                "is required with backend.kind = \"franka\" (or --fault-record): a fault must \
                 survive a restart",
            )?;
        }
        Ok(())
    }

    /// What a daemon that moves a Franka needs of the control law (checked
    /// before the motion, not by the operator's commands): a supervisor
    /// that faults before the robot's own reflex, at `velocity_fault_scale`
    /// below 1 of the robot's speed limits, on an FR3 its position-dependent
    /// ones.
    pub fn validate_for_motion(&self) -> Result<(), DaemonConfigError> {
        if self.backend.kind == BackendKind::Franka {
            // The supervisor must fault before the robot's own reflex,
            // which sits at the robot's speed limits.
            let scale = self.controller.safety.velocity_fault_scale;
            ensure(
                scale < 1.0,
                "controller.safety.velocity_fault_scale",
                scale,
                "must be below 1 with backend.kind = \"franka\" (the robot faults at its \
                 own limit)",
            )?;
            let fr3 = self.backend.franka.generation == FrankaGeneration::Fr3;
            ensure(
                !fr3 || self.controller.joint_speed_limits != SpeedLimitSource::Urdf,
                "controller.joint_speed_limits",
                "\"urdf\"",
                "must be \"fr3\" with backend.franka.generation = \"fr3\" (its speed limits \
                 depend on the joints' positions)",
            )?;
        }
        Ok(())
    }

    /// Checks the daemon's own values (the control law is checked against
    /// the robot model when the controller is built).
    pub fn validate(&self) -> Result<(), DaemonConfigError> {
        ensure(
            !self.robot.is_empty(),
            "robot",
            "\"\"",
            "must name a built-in robot or a URDF file",
        )?;
        if let Some(p) = &self.fault_record {
            ensure(
                !p.as_os_str().is_empty(),
                "fault_record",
                "\"\"",
                "must be a file path (its folder must exist)",
            )?;
        }
        let t = &self.timing;
        positive("timing.hardware_timeout_ms", t.hardware_timeout_ms)?;
        positive("timing.startup_timeout_s", t.startup_timeout_s)?;
        positive("timing.status_period_ms", t.status_period_ms)?;
        positive(
            "timing.lockstep_action_timeout_s",
            t.lockstep_action_timeout_s,
        )?;
        non_negative("timing.shutdown_hold_s", t.shutdown_hold_s)?;
        // Upper bounds: a longer hardware timeout no longer protects the
        // arm (and huge values saturated the nanosecond conversion, which
        // turned the check off); the others keep shutdown and start-up
        // bounded in time.
        within(
            "timing.hardware_timeout_ms",
            t.hardware_timeout_ms,
            0.0..=1000.0,
        )?;
        within(
            "timing.startup_timeout_s",
            t.startup_timeout_s,
            0.0..=3600.0,
        )?;
        within(
            "timing.status_period_ms",
            t.status_period_ms,
            0.0..=10_000.0,
        )?;
        within(
            "timing.lockstep_action_timeout_s",
            t.lockstep_action_timeout_s,
            0.0..=60.0,
        )?;
        within("timing.shutdown_hold_s", t.shutdown_hold_s, 0.0..=60.0)?;
        positive("timing.max_action_age_ms", t.max_action_age_ms)?;
        // Above a second an action is no answer to what the arm does now.
        within(
            "timing.max_action_age_ms",
            t.max_action_age_ms,
            0.0..=1000.0,
        )?;
        at_least("timing.action_period_steps", t.action_period_steps, 1)?;
        // Above `action_period_steps` it acts as the period (a shorter
        // period than the default 25 needs no second setting).
        at_least(
            "timing.min_action_interval_steps",
            t.min_action_interval_steps,
            1,
        )?;
        // SCHED_FIFO priorities are 1 to 99.
        within("realtime.priority", self.realtime.priority, 1..=99)?;
        // The loop runs on the main thread (8 MiB of stack by default); the
        // pre-fault recurses in 16 KiB frames and must stay well inside it.
        within(
            "realtime.prefault_stack_kib",
            self.realtime.prefault_stack_kib,
            0..=2048,
        )?;
        let ns = &self.backend.namespace;
        ensure(
            !ns.is_empty() && !ns.contains(char::is_whitespace),
            "backend.namespace",
            format_args!("{ns:?}"),
            "must be non-empty, without spaces",
        )?;
        if self.backend.kind == BackendKind::Franka {
            // The robot clocks the loop (one cycle per state, 1 kHz) and
            // never waits for the learner.
            ensure(
                t.clock == Clock::Hardware,
                "timing.clock",
                format_args!("{:?}", t.clock),
                "must be \"hardware\" with backend.kind = \"franka\" (the robot clocks the loop)",
            )?;
            ensure(
                !t.lockstep_actions,
                "timing.lockstep_actions",
                "true",
                "must be false with backend.kind = \"franka\" (a robot cannot wait for the \
                 learner)",
            )?;
            ensure(
                (self.controller.period_s - 1e-3).abs() < 1e-12,
                "controller.period_s",
                self.controller.period_s,
                "must be 0.001 with backend.kind = \"franka\" (the robot's cycle)",
            )?;
            self.backend.franka.validate()?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_round_trip_through_toml() {
        let c = DaemonConfig::default();
        let back = DaemonConfig::from_toml(&c.to_toml(), "(printed)").unwrap();
        assert_eq!(c, back);
    }

    #[test]
    fn the_shipped_configuration_loads() {
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../deploy/rt-controller.toml"
        );
        let c = DaemonConfig::from_file(std::path::Path::new(path)).unwrap();
        assert_eq!(c.robot, "iiwa14");
        assert_eq!(c.timing.clock, Clock::Wall);
    }

    #[test]
    fn timing_and_stack_values_are_bounded() {
        for (toml, field) in [
            (
                "[timing]\nhardware_timeout_ms = 1e300\n",
                "timing.hardware_timeout_ms",
            ),
            (
                "[timing]\nshutdown_hold_s = 1e9\n",
                "timing.shutdown_hold_s",
            ),
            (
                "[timing]\nmax_action_age_ms = 5000.0\n",
                "timing.max_action_age_ms",
            ),
            (
                "[realtime]\nprefault_stack_kib = 65536\n",
                "realtime.prefault_stack_kib",
            ),
        ] {
            let e = DaemonConfig::from_toml(toml, "x.toml")
                .unwrap_err()
                .to_string();
            assert!(e.contains(field), "{toml}: {e}");
        }
        let mut c = DaemonConfig::default();
        c.timing.hardware_timeout_ms = 1000.0;
        c.realtime.prefault_stack_kib = 2048;
        c.validate().unwrap();
    }

    #[test]
    fn bad_values_and_unknown_fields_are_named() {
        let e = DaemonConfig::from_toml("[realtime]\npriority = 120\n", "x.toml").unwrap_err();
        assert!(e.to_string().contains("realtime.priority"), "{e}");
        let e = DaemonConfig::from_toml("[timing]\nhardware_timeout_ms = -1.0\n", "x.toml")
            .unwrap_err();
        assert!(e.to_string().contains("timing.hardware_timeout_ms"), "{e}");
        let e = DaemonConfig::from_toml("[timing]\nclok = \"wall\"\n", "x.toml").unwrap_err();
        assert!(e.to_string().contains("clok"), "{e}");
        let e = DaemonConfig::from_toml("[backend]\nkind = \"ur5\"\n", "x.toml").unwrap_err();
        assert!(e.to_string().contains("ur5"), "{e}");
        for (toml, field) in [
            ("[backend]\nkind = \"franka\"\n", "timing.clock"),
            (
                "[backend]\nkind = \"franka\"\n[timing]\nclock = \"hardware\"\nlockstep_actions = true\n",
                "timing.lockstep_actions",
            ),
            (
                "[backend]\nkind = \"franka\"\n[timing]\nclock = \"hardware\"\n\
                 [backend.franka]\ncutoff_hz = 0.0\n",
                "backend.franka.cutoff_hz",
            ),
            (
                "[backend]\nkind = \"franka\"\n[timing]\nclock = \"hardware\"\n\
                 [backend.franka]\ncollision_force = [20.0, 20.0, 20.0, 25.0, 25.0, 1.0]\n",
                "backend.franka.collision_force",
            ),
            (
                "[backend]\nkind = \"franka\"\n[timing]\nclock = \"hardware\"\n\
                 [backend.franka]\naddress = \"\"\n",
                "backend.franka.address",
            ),
            (
                "[backend]\nkind = \"franka\"\n[timing]\nclock = \"hardware\"\n\
                 [backend.franka]\nwrench = \"net_ft\"\n\
                 [backend.franka.net_ft]\ncounts_per_force = 0.0\n",
                "backend.franka.net_ft.counts_per_force",
            ),
            (
                "[backend]\nkind = \"franka\"\n[timing]\nclock = \"hardware\"\n\
                 [backend.franka]\nwrench = \"net_ft\"\n\
                 [backend.franka.net_ft]\naddress = \"a b\"\n",
                "backend.franka.net_ft.address",
            ),
        ] {
            let e = DaemonConfig::from_toml(toml, "x.toml")
                .unwrap_err()
                .to_string();
            assert!(e.contains(field), "{toml}: {e}");
        }
        // The sensor's settings are read whatever the source, and checked
        // only when it is the source.
        let c = DaemonConfig::from_toml(
            "[backend]\nkind = \"franka\"\n[timing]\nclock = \"hardware\"\n\
             [backend.franka]\nwrench = \"net_ft\"\n\
             [backend.franka.net_ft]\naddress = \"10.0.0.5\"\ncounts_per_torque = 1e6\n",
            "x.toml",
        )
        .unwrap();
        assert_eq!(c.backend.franka.wrench, WrenchSource::NetFt);
        assert_eq!(c.backend.franka.net_ft.address, "10.0.0.5");
        let e = DaemonConfig::from_toml("[backend.franka]\ngeneration = \"fr2\"\n", "x.toml")
            .unwrap_err();
        assert!(e.to_string().contains("fr2"), "{e}");
        let e = DaemonConfig::from_file(std::path::Path::new("/nonexistent/rt.toml")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/rt.toml"), "{e}");
    }
}
