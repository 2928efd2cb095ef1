//! Joint speed limits: the URDF's constant ones, or a robot's own
//! position-dependent ones (the Franka Research 3 slows a joint down as it
//! nears a position limit, and faults a joint that is faster). The QP keeps
//! to these limits and the supervisor faults on them, so the controller
//! acts before the robot's own reflex does. Built once; evaluating a limit
//! is a few flops and never allocates.

use crate::config::{ConfigError, RampLimit, SpeedLimitSource};
use robot_model::Model;
use shared_mem_schema::config::{FieldError, check, non_negative, positive};

/// One joint's speed limit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JointSpeedLimit {
    /// `±v_max` at every position, rad/s.
    Constant(f64),
    /// Position-dependent: near a stop the joint may move towards it no
    /// faster than lets it stop there (see [`RampLimit`]); the controller
    /// keeps [`RAMP_MARGIN`] inside it.
    Ramp(RampLimit),
}

impl JointSpeedLimit {
    /// The robot's own (upper, lower) velocity limits at `q`, no margin.
    fn raw(&self, q: f64) -> (f64, f64) {
        match *self {
            Self::Constant(v) => (v, -v),
            Self::Ramp(r) => {
                let up = (2.0 * r.decel * (r.q_hi - q)).max(0.0).sqrt();
                let down = (2.0 * r.decel * (q - r.q_lo)).max(0.0).sqrt();
                (
                    (up - r.offset).max(0.0).min(r.v_max),
                    (r.offset - down).min(0.0).max(-r.v_max),
                )
            }
        }
    }

    fn margin(&self) -> f64 {
        match self {
            Self::Constant(_) => 0.0,
            Self::Ramp(_) => RAMP_MARGIN,
        }
    }

    /// Largest velocity the controller allows at position `q` (slightly
    /// negative at the stop of a ramp: the joint must move back).
    pub fn upper(&self, q: f64) -> f64 {
        self.raw(q).0 - self.margin()
    }

    /// Smallest (most negative) velocity the controller allows at `q`.
    pub fn lower(&self, q: f64) -> f64 {
        self.raw(q).1 + self.margin()
    }

    /// The robot's own largest velocity at `q`, where its reflex sits: no
    /// margin, and never below zero, so that a joint at rest right at its
    /// stop is no fault.
    pub fn robot_upper(&self, q: f64) -> f64 {
        self.raw(q).0
    }

    /// The robot's own smallest velocity at `q` (see [`Self::robot_upper`]).
    pub fn robot_lower(&self, q: f64) -> f64 {
        self.raw(q).1
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

/// The FR3's limits as Franka documents them (libfranka 0.10–0.15's
/// `rate_limiting.h`, where `2·decel` appears folded in: 12.0, 5.17, 7.00,
/// 8.00, 34.0, 11.0, 34.0).
pub const FR3_RAMPS: [RampLimit; 7] = [
    ramp(-2.7501, 2.7501, 2.62, 0.30, 6.0),
    ramp(-1.7918, 1.7918, 2.62, 0.20, 2.585),
    ramp(-2.9065, 2.9065, 2.62, 0.20, 3.5),
    ramp(-3.0481, -0.1458, 2.62, 0.30, 4.0),
    ramp(-2.8101, 2.8101, 5.26, 0.35, 17.0),
    ramp(0.54092, 4.5205, 4.18, 0.35, 5.5),
    ramp(-3.0196, 3.0196, 5.26, 0.35, 17.0),
];

const fn ramp(q_lo: f64, q_hi: f64, v_max: f64, offset: f64, decel: f64) -> RampLimit {
    RampLimit {
        q_lo,
        q_hi,
        v_max,
        offset,
        decel,
    }
}

/// libfranka's `kJointVelocityLimitsTolerance` for the FR3 (`kLimitEps`,
/// no lost-packet allowance), rad/s: the controller keeps this far inside
/// a position-dependent limit.
pub const RAMP_MARGIN: f64 = 1e-3;

/// Every joint's speed limit, in the model's joint order.
#[derive(Debug, Clone, PartialEq)]
pub struct SpeedLimits {
    joints: Vec<JointSpeedLimit>,
}

impl SpeedLimits {
    /// The limits `source` names for `model`. The FR3's need a model of
    /// the FR3: seven joints whose URDF speeds are the FR3's (a Panda's
    /// model with the FR3's limits is refused, naming the joint); ramps of
    /// a robot's own need one per joint, finite, each with `q_lo < q_hi`,
    /// `v_max` and `decel` positive and `offset` not negative.
    pub fn new(source: &SpeedLimitSource, model: &Model) -> Result<Self, ConfigError> {
        let urdf = model.velocity_limits();
        let ramps: &[RampLimit] = match source {
            SpeedLimitSource::Urdf => {
                let joints = urdf
                    .iter()
                    .map(|&v_max| JointSpeedLimit::Constant(v_max))
                    .collect();
                return Ok(Self { joints });
            }
            SpeedLimitSource::Fr3 => {
                for (k, (r, &v)) in FR3_RAMPS.iter().zip(urdf.iter()).enumerate() {
                    if (v - r.v_max).abs() > 1e-6 {
                        return Err(ConfigError::BadValue(FieldError::new(
                            "joint_speed_limits",
                            "fr3",
                            format!(
                                "needs the FR3's model: joint {k}'s URDF speed is {v} rad/s, \
                                 the FR3's {}",
                                r.v_max
                            ),
                        )));
                    }
                }
                &FR3_RAMPS
            }
            SpeedLimitSource::Ramps(r) => r,
        };
        if ramps.len() != urdf.len() {
            return Err(ConfigError::WrongLength {
                field: "joint_speed_limits".into(),
                got: ramps.len(),
                expected: urdf.len(),
            });
        }
        let mut joints = Vec::with_capacity(ramps.len());
        for (k, r) in ramps.iter().enumerate() {
            let field = |name: &str| format!("joint_speed_limits.ramps[{k}].{name}");
            let ok = [r.q_lo, r.q_hi, r.v_max, r.offset, r.decel]
                .iter()
                .all(|x| x.is_finite());
            check(
                &field("q_lo"),
                r.q_lo,
                ok && r.q_lo < r.q_hi,
                "must be finite and below q_hi",
            )?;
            positive(&field("v_max"), r.v_max)?;
            non_negative(&field("offset"), r.offset)?;
            positive(&field("decel"), r.decel)?;
            joints.push(JointSpeedLimit::Ramp(*r));
        }
        Ok(Self { joints })
    }

    /// Joint `k`'s limit; `None` past the last joint.
    pub fn joint(&self, k: usize) -> Option<&JointSpeedLimit> {
        self.joints.get(k)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use robot_model::descriptions::{FR3_READY_Q, builtin};

    fn fr3() -> SpeedLimits {
        SpeedLimits::new(&SpeedLimitSource::Fr3, &builtin("fr3").unwrap()).unwrap()
    }

    #[test]
    fn away_from_the_limits_the_fr3_allows_its_largest_speed_less_the_margin() {
        let l = fr3();
        let caps = [2.62, 2.62, 2.62, 2.62, 5.26, 4.18, 5.26];
        for (k, cap) in caps.iter().enumerate() {
            let j = l.joint(k).unwrap();
            // Joint 6's lower limit already ramps at the ready pose (q =
            // 1.57 rad, 1.03 rad from its stop: 0.35 − √(11·1.03)).
            let mid = 0.5 * (FR3_RAMPS[k].q_lo + FR3_RAMPS[k].q_hi);
            assert!((j.upper(mid) - (cap - 1e-3)).abs() < 1e-12, "joint {k}");
            assert!((j.lower(mid) + (cap - 1e-3)).abs() < 1e-12, "joint {k}");
        }
        let q5 = FR3_READY_Q[5];
        let want = 0.35 - (11.0 * (q5 - 0.54092)).sqrt() + 1e-3;
        assert!((l.joint(5).unwrap().lower(q5) - want).abs() < 1e-12);
    }

    #[test]
    fn near_a_position_limit_the_fr3_limit_ramps_to_zero_and_past_it() {
        let j = *fr3().joint(0).unwrap();
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
        // The robot's own limit, where the supervisor faults: no margin,
        // and a joint at rest at its stop is within it.
        assert!((j.robot_upper(2.7) - (want + 1e-3)).abs() < 1e-12);
        assert_eq!(j.robot_upper(2.7501), 0.0);
        assert_eq!(j.robot_lower(-3.0), 0.0);
        assert_eq!(j.robot_lower(0.0), -2.62);
    }

    #[test]
    fn the_urdf_limits_are_constant_and_the_fr3_ones_need_the_fr3() {
        let panda = builtin("panda").unwrap();
        let l = SpeedLimits::new(&SpeedLimitSource::Urdf, &panda).unwrap();
        let v0 = panda.velocity_limits()[0];
        assert_eq!(l.joint(0).unwrap().upper(10.0), v0);
        assert_eq!(l.joint(0).unwrap().lower(-10.0), -v0);
        let e = SpeedLimits::new(&SpeedLimitSource::Fr3, &panda)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("joint_speed_limits") && e.contains("joint 0"),
            "{e}"
        );
        let iiwa = builtin("iiwa14").unwrap();
        assert!(SpeedLimits::new(&SpeedLimitSource::Fr3, &iiwa).is_err());
    }

    #[test]
    fn a_robots_own_ramps_are_used_and_checked_by_name() {
        let fr3 = builtin("fr3").unwrap();
        let mut ramps = FR3_RAMPS.to_vec();
        // An FR3 that serves a larger offset on joint 0 (as some do).
        ramps[0].offset = 0.652;
        let l = SpeedLimits::new(&SpeedLimitSource::Ramps(ramps.clone()), &fr3).unwrap();
        let want = -0.652 + (12.0 * (2.7501_f64 - 2.7)).sqrt() - 1e-3;
        assert!((l.joint(0).unwrap().upper(2.7) - want).abs() < 1e-12);
        for (k, field, bad) in [
            (2, "q_lo", f64::NAN),
            (3, "q_lo", 0.0),
            (4, "v_max", -1.0),
            (5, "offset", -0.1),
            (6, "decel", 0.0),
        ] {
            let mut r = ramps.clone();
            match field {
                "q_lo" if bad == 0.0 => r[k].q_lo = r[k].q_hi + 1.0,
                "q_lo" => r[k].q_lo = bad,
                "v_max" => r[k].v_max = bad,
                "offset" => r[k].offset = bad,
                _ => r[k].decel = bad,
            }
            let e = SpeedLimits::new(&SpeedLimitSource::Ramps(r), &fr3)
                .unwrap_err()
                .to_string();
            let name = format!("joint_speed_limits.ramps[{k}].{field}");
            assert!(e.contains(&name), "{e}");
        }
        let e = SpeedLimits::new(&SpeedLimitSource::Ramps(ramps[..6].to_vec()), &fr3)
            .unwrap_err()
            .to_string();
        assert!(e.contains("joint_speed_limits") && e.contains('6'), "{e}");
    }

    #[test]
    fn scaling_narrows_a_limit_but_never_loosens_one_that_asks_to_move_back() {
        assert_eq!(scaled(2.0, 0.9, true), 1.8);
        assert_eq!(scaled(-2.0, 0.9, false), -1.8);
        assert_eq!(scaled(-1e-3, 0.9, true), -1e-3);
        assert_eq!(scaled(1e-3, 1.2, false), 1e-3);
    }
}
