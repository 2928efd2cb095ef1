//! Joint speed limits: the URDF's constant ones, or a robot's own
//! position-dependent ones (the Franka Research 3 slows a joint down as it
//! nears a position limit, and faults a joint that is faster). The QP keeps
//! to these limits and the supervisor faults on them, so the controller
//! acts before the robot's own reflex does. Built once; evaluating a limit
//! is a few flops and never allocates.

use crate::config::{ConfigError, SpeedLimitSource};
use robot_model::Model;
use shared_mem_schema::config::FieldError;

/// Near a position limit a joint may move towards it no faster than lets it
/// stop there: `−offset + √(2·decel·distance)`, capped by the joint's
/// largest speed, less `margin`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ramp {
    /// Lower position limit of the ramp, rad (the robot's, not the URDF's).
    pub q_lo: f64,
    /// Upper position limit of the ramp, rad.
    pub q_hi: f64,
    /// Speed offset, rad/s.
    pub offset: f64,
    /// Deceleration, rad/s².
    pub decel: f64,
    /// Taken off the limit on both sides (libfranka's
    /// `kJointVelocityLimitsTolerance`), rad/s.
    pub margin: f64,
}

/// One joint's speed limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointSpeedLimit {
    /// Largest speed anywhere, rad/s.
    pub v_max: f64,
    /// The position-dependent part; `None`: constant `±v_max`.
    pub ramp: Option<Ramp>,
}

impl JointSpeedLimit {
    /// Largest allowed velocity at position `q` (may be slightly negative
    /// at the limit: the joint must move back).
    pub fn upper(&self, q: f64) -> f64 {
        match self.ramp {
            None => self.v_max,
            Some(r) => {
                let stop = (2.0 * r.decel * (r.q_hi - q)).max(0.0).sqrt();
                (stop - r.offset).max(0.0).min(self.v_max) - r.margin
            }
        }
    }

    /// Smallest (most negative) allowed velocity at position `q`.
    pub fn lower(&self, q: f64) -> f64 {
        match self.ramp {
            None => -self.v_max,
            Some(r) => {
                let stop = (2.0 * r.decel * (q - r.q_lo)).max(0.0).sqrt();
                (r.offset - stop).min(0.0).max(-self.v_max) + r.margin
            }
        }
    }
}

/// A limit scaled towards zero by `scale` where it is a limit away from
/// zero; a limit that already asks the joint to move back (the wrong sign,
/// at a position limit) is kept as it is, never loosened.
pub fn scaled(limit: f64, scale: f64, upper: bool) -> f64 {
    if (upper && limit > 0.0) || (!upper && limit < 0.0) {
        limit * scale
    } else {
        limit
    }
}

/// The FR3's joints: position limits, largest speed, offset and
/// deceleration of Franka's documented limits (the numbers of libfranka
/// 0.10–0.15's `rate_limiting.h`, where `2·decel` appears folded in: 12.0,
/// 5.17, 7.00, 8.00, 34.0, 11.0, 34.0).
const FR3: [(f64, f64, f64, f64, f64); 7] = [
    (-2.7501, 2.7501, 2.62, 0.30, 6.0),
    (-1.7918, 1.7918, 2.62, 0.20, 2.585),
    (-2.9065, 2.9065, 2.62, 0.20, 3.5),
    (-3.0481, -0.1458, 2.62, 0.30, 4.0),
    (-2.8101, 2.8101, 5.26, 0.35, 17.0),
    (0.54092, 4.5205, 4.18, 0.35, 5.5),
    (-3.0196, 3.0196, 5.26, 0.35, 17.0),
];

/// libfranka's `kJointVelocityLimitsTolerance` for the FR3 (`kLimitEps`,
/// no lost-packet allowance), rad/s.
const FR3_MARGIN: f64 = 1e-3;

/// Every joint's speed limit, in the model's joint order.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedLimits {
    joints: Vec<JointSpeedLimit>,
}

impl SpeedLimits {
    /// The limits `source` names for `model`. The FR3's need a model of
    /// the FR3: seven joints whose URDF speeds are the FR3's (a Panda's
    /// model with the FR3's limits is refused, naming the joint).
    pub fn new(source: SpeedLimitSource, model: &Model) -> Result<Self, ConfigError> {
        let urdf = model.velocity_limits();
        let joints = match source {
            SpeedLimitSource::Urdf => urdf
                .iter()
                .map(|&v_max| JointSpeedLimit { v_max, ramp: None })
                .collect(),
            SpeedLimitSource::Fr3 => {
                if urdf.len() != FR3.len() {
                    return Err(ConfigError::WrongLength {
                        field: "joint_speed_limits (\"fr3\")".into(),
                        got: FR3.len(),
                        expected: urdf.len(),
                    });
                }
                let mut joints = Vec::with_capacity(FR3.len());
                for (k, (&(q_lo, q_hi, v_max, offset, decel), &v)) in
                    FR3.iter().zip(urdf.iter()).enumerate()
                {
                    if (v - v_max).abs() > 1e-6 {
                        return Err(ConfigError::BadValue(FieldError::new(
                            "joint_speed_limits",
                            "fr3",
                            format!(
                                "needs the FR3's model: joint {k}'s URDF speed is {v} rad/s, \
                                 the FR3's {v_max}"
                            ),
                        )));
                    }
                    let ramp = Ramp {
                        q_lo,
                        q_hi,
                        offset,
                        decel,
                        margin: FR3_MARGIN,
                    };
                    joints.push(JointSpeedLimit {
                        v_max,
                        ramp: Some(ramp),
                    });
                }
                joints
            }
        };
        Ok(Self { joints })
    }

    /// Joint `k`'s limit.
    pub fn joint(&self, k: usize) -> &JointSpeedLimit {
        &self.joints[k]
    }

    /// The number of joints.
    pub fn len(&self) -> usize {
        self.joints.len()
    }

    /// True for a robot without joints.
    pub fn is_empty(&self) -> bool {
        self.joints.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use robot_model::descriptions::{FR3_READY_Q, builtin};

    fn fr3() -> SpeedLimits {
        SpeedLimits::new(SpeedLimitSource::Fr3, &builtin("fr3").unwrap()).unwrap()
    }

    #[test]
    fn away_from_the_limits_the_fr3_allows_its_largest_speed_less_the_margin() {
        let l = fr3();
        let caps = [2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26];
        for (k, cap) in caps.iter().enumerate() {
            let j = l.joint(k);
            // Joint 6's lower limit already ramps at the ready pose (q =
            // 1.57 rad, 1.03 rad from its stop: 0.35 − √(11·1.03)).
            let mid = 0.5 * (FR3[k].0 + FR3[k].1);
            assert!((j.upper(mid) - (cap - 1e-3)).abs() < 1e-12, "joint {k}");
            assert!((j.lower(mid) + (cap - 1e-3)).abs() < 1e-12, "joint {k}");
        }
        let q5 = FR3_READY_Q[5];
        let want = 0.35 - (11.0 * (q5 - 0.54092)).sqrt() + 1e-3;
        assert!((l.joint(5).lower(q5) - want).abs() < 1e-12);
    }

    #[test]
    fn near_a_position_limit_the_fr3_limit_ramps_to_zero_and_past_it() {
        let j = *fr3().joint(0);
        // libfranka: −0.30 + √(12·(2.7501 − 2.7)) − 0.001.
        let want = -0.30 + (12.0 * (2.7501_f64 - 2.7)).sqrt() - 1e-3;
        assert!((j.upper(2.7) - want).abs() < 1e-12);
        assert!(j.upper(2.7) < 0.5);
        // At and past the stop the joint may only move back.
        assert_eq!(j.upper(2.7501), -1e-3);
        assert_eq!(j.upper(3.0), -1e-3);
        // The lower side mirrors it.
        assert!((j.lower(-2.7) + want).abs() < 1e-12);
        // Moving away from the near stop keeps the full speed.
        assert!((j.lower(2.7) + 2.619).abs() < 1e-12);
    }

    #[test]
    fn the_urdf_limits_are_constant_and_the_fr3_ones_need_the_fr3() {
        let panda = builtin("panda").unwrap();
        let l = SpeedLimits::new(SpeedLimitSource::Urdf, &panda).unwrap();
        let v0 = panda.velocity_limits()[0];
        assert_eq!(l.joint(0).upper(10.0), v0);
        assert_eq!(l.joint(0).lower(-10.0), -v0);
        let e = SpeedLimits::new(SpeedLimitSource::Fr3, &panda)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("joint_speed_limits") && e.contains("joint 0"),
            "{e}"
        );
        let iiwa = builtin("iiwa14").unwrap();
        assert!(SpeedLimits::new(SpeedLimitSource::Fr3, &iiwa).is_err());
    }

    #[test]
    fn scaling_narrows_a_limit_but_never_loosens_one_that_asks_to_move_back() {
        assert_eq!(scaled(2.0, 0.9, true), 1.8);
        assert_eq!(scaled(-2.0, 0.9, false), -1.8);
        assert_eq!(scaled(-1e-3, 0.9, true), -1e-3);
        assert_eq!(scaled(1e-3, 1.2, false), 1e-3);
    }
}
