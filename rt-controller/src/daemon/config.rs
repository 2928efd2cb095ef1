//! The daemon's TOML configuration: robot, control law, backend, timing and
//! real-time settings. Every field is documented and defaulted; unknown
//! fields are errors and bad values name their dotted field.

use crate::config::ControllerConfig;
use serde::{Deserialize, Serialize};

/// A daemon configuration value it cannot run with.
#[derive(Debug, thiserror::Error)]
pub enum DaemonConfigError {
    /// The file could not be read.
    #[error("cannot read the configuration {path}: {source}")]
    Read {
        /// The file.
        path: String,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TOML is malformed, has an unknown field or a wrong type.
    #[error("configuration {path}: {message}")]
    Parse {
        /// The file (or "(text)").
        path: String,
        /// The parser's message (names the field).
        message: String,
    },
    /// A value is out of range.
    #[error("configuration: `{field}` = {value} is invalid: {reason}")]
    BadValue {
        /// Dotted field name.
        field: &'static str,
        /// The value, as text.
        value: String,
        /// What it must satisfy.
        reason: &'static str,
    },
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
    /// A Franka Panda through libfranka (its own issue; not built yet).
    Franka,
}

/// The hardware backend.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BackendConfig {
    /// `sim` or `franka`.
    pub kind: BackendKind,
    /// Service namespace shared with the simulator and the learner.
    pub namespace: String,
}

impl Default for BackendConfig {
    fn default() -> Self {
        Self {
            kind: BackendKind::Sim,
            namespace: shared_mem_schema::DEFAULT_NAMESPACE.into(),
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
    /// Hardware steps per policy action (50 at 1 kHz = 20 Hz).
    pub action_period_steps: u64,
    /// Lockstep only: how long to wait for an addressed action, s.
    pub lockstep_action_timeout_s: f64,
    /// On SIGTERM/SIGINT: hold the pose this long before exiting, s.
    pub shutdown_hold_s: f64,
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
            lockstep_action_timeout_s: 5.0,
            shutdown_hold_s: 0.3,
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
}

impl Default for DaemonConfig {
    fn default() -> Self {
        Self {
            robot: "iiwa14".into(),
            controller: ControllerConfig::default(),
            backend: BackendConfig::default(),
            timing: TimingConfig::default(),
            realtime: RealtimeConfig::default(),
        }
    }
}

fn positive(field: &'static str, v: f64) -> Result<(), DaemonConfigError> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(DaemonConfigError::BadValue {
            field,
            value: v.to_string(),
            reason: "must be finite and > 0",
        })
    }
}

impl DaemonConfig {
    /// Parses TOML text; `origin` names it in errors.
    pub fn from_toml(text: &str, origin: &str) -> Result<Self, DaemonConfigError> {
        let c: Self = toml::from_str(text).map_err(|e| DaemonConfigError::Parse {
            path: origin.into(),
            message: e.to_string(),
        })?;
        c.validate()?;
        Ok(c)
    }

    /// Reads and parses a file.
    pub fn from_file(path: &std::path::Path) -> Result<Self, DaemonConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| DaemonConfigError::Read {
            path: path.display().to_string(),
            source,
        })?;
        Self::from_toml(&text, &path.display().to_string())
    }

    /// The configuration as TOML (what the daemon prints at start).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).unwrap_or_else(|e| format!("# cannot print: {e}\n"))
    }

    /// Checks the daemon's own values (the control law is checked against
    /// the robot model when the controller is built).
    pub fn validate(&self) -> Result<(), DaemonConfigError> {
        if self.robot.is_empty() {
            return Err(DaemonConfigError::BadValue {
                field: "robot",
                value: "\"\"".into(),
                reason: "must name a built-in robot or a URDF file",
            });
        }
        let t = &self.timing;
        positive("timing.hardware_timeout_ms", t.hardware_timeout_ms)?;
        positive("timing.startup_timeout_s", t.startup_timeout_s)?;
        positive("timing.status_period_ms", t.status_period_ms)?;
        positive(
            "timing.lockstep_action_timeout_s",
            t.lockstep_action_timeout_s,
        )?;
        if !(t.shutdown_hold_s.is_finite() && t.shutdown_hold_s >= 0.0) {
            return Err(DaemonConfigError::BadValue {
                field: "timing.shutdown_hold_s",
                value: t.shutdown_hold_s.to_string(),
                reason: "must be finite and >= 0",
            });
        }
        if t.action_period_steps == 0 {
            return Err(DaemonConfigError::BadValue {
                field: "timing.action_period_steps",
                value: "0".into(),
                reason: "must be >= 1",
            });
        }
        let r = &self.realtime;
        if !(1..=99).contains(&r.priority) {
            return Err(DaemonConfigError::BadValue {
                field: "realtime.priority",
                value: r.priority.to_string(),
                reason: "SCHED_FIFO priorities are 1 to 99",
            });
        }
        if self.backend.namespace.is_empty() || self.backend.namespace.contains(char::is_whitespace)
        {
            return Err(DaemonConfigError::BadValue {
                field: "backend.namespace",
                value: format!("{:?}", self.backend.namespace),
                reason: "must be non-empty, without spaces",
            });
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
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../deploy/rt-controller.toml");
        let c = DaemonConfig::from_file(std::path::Path::new(path)).unwrap();
        assert_eq!(c.robot, "iiwa14");
        assert_eq!(c.timing.clock, Clock::Wall);
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
        let e = DaemonConfig::from_file(std::path::Path::new("/nonexistent/rt.toml")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/rt.toml"), "{e}");
    }
}
