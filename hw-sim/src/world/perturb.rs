//! Perturbations: pushes on the arm (scheduled and random) and camera
//! occlusions, drawn per episode from the seed.

use super::*;
use crate::config::Occlusion;

#[derive(Clone, Copy, Debug)]
pub(super) struct ScheduledPush {
    start_s: f64,
    duration_s: f64,
    link: usize,
    force: Vector3<f64>,
}

impl World {
    /// Draws the episode's pushes and occlusions from `cfg` and `rng`.
    pub(super) fn schedule_perturbations(&mut self, cfg: &WorldConfig, rng: &mut SimRng) {
        let nv = self.model.nv();
        let p = &cfg.perturbations;
        self.pushes = p
            .pushes
            .iter()
            .map(|push| ScheduledPush {
                start_s: push.start_s,
                duration_s: push.duration_s,
                link: push.link,
                force: Vector3::from(push.force_n),
            })
            .collect();
        for _ in 0..p.random_pushes {
            let start = rng::uniform(rng, p.random_window_s[0], p.random_window_s[1]);
            let mag = rng::uniform(rng, p.random_push_force_n[0], p.random_push_force_n[1]);
            let dir = rng::uniform(rng, 0.0, std::f64::consts::TAU);
            self.pushes.push(ScheduledPush {
                start_s: start,
                duration_s: p.random_push_duration_s,
                link: nv,
                force: Vector3::new(mag * dir.cos(), mag * dir.sin(), 0.0),
            });
        }
        self.occlusions = p.occlusions.clone();
        for _ in 0..p.random_occlusions {
            let start = rng::uniform(rng, p.random_window_s[0], p.random_window_s[1]);
            let side = p.random_occlusion_side_px;
            let x = (rng::unit(rng) * cfg.camera.width.saturating_sub(side) as f64) as u32;
            let y = (rng::unit(rng) * cfg.camera.height.saturating_sub(side) as f64) as u32;
            self.occlusions.push(Occlusion {
                start_s: start,
                end_s: start + p.random_occlusion_duration_s,
                rect: Some([x, y, side, side]),
            });
        }
    }

    /// Applies the pushes active in the step from `t` to `t + dt`.
    pub(super) fn apply_pushes(&mut self, t: f64, dt: f64) {
        for push in &self.pushes {
            let body = self.bodies[push.link];
            let rb = &mut self.physics.bodies[body];
            let origin = rb.position().translation;
            if push.duration_s == 0.0 {
                if t <= push.start_s && push.start_s < t + dt {
                    rb.apply_impulse_at_point(to_glam(&push.force), origin, false);
                }
            } else if t + 0.5 * dt >= push.start_s && t + 0.5 * dt < push.start_s + push.duration_s
            {
                rb.add_force_at_point(to_glam(&push.force), origin, false);
            }
        }
    }

    /// The occlusions active at simulated time `t_s`.
    pub fn occlusions_at(&self, t_s: f64) -> impl Iterator<Item = &Occlusion> {
        self.occlusions
            .iter()
            .filter(move |o| o.start_s <= t_s && t_s < o.end_s)
    }
}
