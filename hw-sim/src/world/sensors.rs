//! The sensors: the wrist F/T wrench from the peg's Newton–Euler
//! equations, its low-pass filter, bias and noise, and the joint readings.

use super::*;
use rapier3d_f64::geometry::NEW_CONTACT_BIT;
use rapier3d_f64::prelude::{ColliderHandle, PairContacts};
use rapier3d_f64::utils::OrthonormalBasis;

/// What the sensors read at the current step (noise and bias included).
#[derive(Clone, Debug, PartialEq)]
pub struct SensorReadings {
    /// Simulated time, s.
    pub t_s: f64,
    /// Joint positions, rad.
    pub q: Vec<f64>,
    /// Joint velocities, rad/s.
    pub v: Vec<f64>,
    /// Torques applied in the last step (after saturation), N·m.
    pub tau_applied: Vec<f64>,
    /// Wrench the peg exerts on the flange, in the sensor frame (fx, fy,
    /// fz in N, mx, my, mz in N·m about the sensor origin).
    pub wrench: [f64; 6],
}

impl World {
    /// The noise streams and the F/T filter of an episode.
    pub(super) fn reset_sensors(&mut self, seed: u64) {
        self.noise_rngs = [3, 5, 6, 7].map(|k| rng::seeded(seed, k));
        // No draw for a fixed scale: configurations without a range keep
        // every episode exactly as before the range existed.
        let [lo, hi] = self.config.noise.episode_scale;
        self.noise_scale = if hi > lo {
            rng::uniform(&mut rng::seeded(seed, 8), lo, hi)
        } else {
            lo
        };
        let hz = self.config.noise.ft_filter_hz;
        self.ft_alpha = if hz > 0.0 {
            1.0 - (-std::f64::consts::TAU * hz * self.config.dt_s).exp()
        } else {
            1.0
        };
    }

    /// (COM velocity, angular velocity, COM position) of the peg, world.
    pub(super) fn peg_motion(&self) -> Option<(Vector3<f64>, Vector3<f64>, Vector3<f64>)> {
        let peg = self.peg.as_ref()?;
        let rb = &self.physics.bodies[self.bodies[peg.info.link]];
        let pose = pose_from_glam(rb.position());
        let c = pose * (peg.info.sensor_in_link * nalgebra::Point3::from(peg.info.com_sensor));
        let body_com = from_glam(rb.mass_properties().world_com);
        let w = from_glam(rb.angvel());
        let v = from_glam(rb.linvel()) + w.cross(&(c.coords - body_com));
        Some((v, w, c.coords))
    }

    /// The F/T reading at rest (weight only), used right after a reset.
    pub(super) fn static_wrench(&self) -> [f64; 6] {
        match self.peg_motion() {
            Some(m) => self.compute_wrench(Some(m), Some(m)),
            None => [0.0; 6],
        }
    }

    /// Wrench the peg exerts on the flange, from the peg's Newton–Euler
    /// equations: contact forces (normal and friction, per contact point),
    /// its weight, minus its inertial forces.
    pub(super) fn compute_wrench(
        &self,
        before: Option<(Vector3<f64>, Vector3<f64>, Vector3<f64>)>,
        after: Option<(Vector3<f64>, Vector3<f64>, Vector3<f64>)>,
    ) -> [f64; 6] {
        let (Some(peg), Some(before), Some(after)) = (self.peg.as_ref(), before, after) else {
            return [0.0; 6];
        };
        let dt = self.config.dt_s;
        let link_pose = pose_from_glam(self.physics.bodies[self.bodies[peg.info.link]].position());
        let sensor = link_pose * peg.info.sensor_in_link;
        let o = sensor.translation.vector;
        let (mut f, mut m) = (Vector3::zeros(), Vector3::zeros());
        for &h in &peg.colliders {
            let (cf, cm) = self.contact_wrench_on(h, &o);
            f += cf;
            m += cm;
        }
        let f_c = f / dt;
        let m_c = m / dt;
        let mass = peg.info.mass_kg;
        let a = (after.0 - before.0) / dt;
        let alpha = (after.1 - before.1) / dt;
        let w = after.1;
        let r = sensor.rotation.to_rotation_matrix();
        let inertia = r * peg.info.inertia_sensor * r.transpose();
        let lin = mass * (self.gravity - a);
        let force = f_c + lin;
        let moment = m_c + (after.2 - o).cross(&lin) - (inertia * alpha + w.cross(&(inertia * w)));
        let fs = r.transpose() * force;
        let ms = r.transpose() * moment;
        [fs.x, fs.y, fs.z, ms.x, ms.y, ms.z]
    }

    /// Sum of the contact impulses (normal and tangential) on collider `h`
    /// in the last step and their moment about `o`, world frame, N·s.
    pub(super) fn contact_wrench_on(
        &self,
        h: ColliderHandle,
        o: &Vector3<f64>,
    ) -> (Vector3<f64>, Vector3<f64>) {
        let (mut f, mut m) = (Vector3::zeros(), Vector3::zeros());
        for pair in self.physics.narrow_phase.contact_pairs_with(h) {
            let PairContacts::Rigid(rigid) = &pair.contacts else {
                continue;
            };
            // rapier stores impulses as applied to collider1's body.
            let sign = if pair.collider1 == h { 1.0 } else { -1.0 };
            for manifold in rigid.solver_manifolds() {
                let dir1 = -manifold.data.normal;
                let t1 = dir1.orthonormal_vector();
                let t2 = dir1.cross(t1);
                for sc in &manifold.data.solver_contacts {
                    let id = (sc.contact_id[0] & !NEW_CONTACT_BIT) as usize;
                    let Some(point) = manifold.points.get(id) else {
                        continue;
                    };
                    let d = &point.data;
                    let imp =
                        dir1 * d.impulse + t1 * d.tangent_impulse[0] + t2 * d.tangent_impulse[1];
                    let (p1, p2) = manifold
                        .data
                        .solver_contact_world_points(sc, &self.physics.bodies);
                    let p = from_glam((p1 + p2) * 0.5);
                    let imp = from_glam(imp) * sign;
                    f += imp;
                    m += (p - o).cross(&imp);
                }
            }
        }
        (f, m)
    }

    pub(super) fn update_readings(&mut self) {
        let n = &self.config.noise;
        let k = self.noise_scale;
        let r = &mut self.readings;
        r.t_s = self.step_index as f64 * self.config.dt_s;
        // One stream per channel, drawn only when its noise is on: noise-free
        // channels cost nothing and turning one on leaves the others' draws.
        let [q_rng, v_rng, f_rng, m_rng] = &mut self.noise_rngs;
        let draw = |rng: &mut SimRng, std: f64| {
            if std > 0.0 {
                std * rng::normal(rng)
            } else {
                0.0
            }
        };
        for j in 0..self.q.len() {
            r.q[j] = self.q[j] + draw(q_rng, k * n.q_std_rad);
            r.v[j] = self.v[j] + draw(v_rng, k * n.v_std_rad_s);
            r.tau_applied[j] = self.tau_applied[j];
        }
        let alpha = self.ft_alpha;
        for i in 0..6 {
            self.wrench_filtered[i] += alpha * (self.wrench_true[i] - self.wrench_filtered[i]);
            let noise = if i < 3 {
                draw(f_rng, k * n.force_std_n)
            } else {
                draw(m_rng, k * n.torque_std_nm)
            };
            r.wrench[i] = self.wrench_filtered[i] + n.ft_bias[i] + noise;
        }
    }
}
