//! Writes a few camera frames of a scripted motion (RGB, depth, flow as
//! colour) to PNG files so a person can look at them:
//!
//! ```text
//! cargo run -p hw-sim --release --example render_frames -- [out_dir] [peg]
//! ```
//!
//! `peg` is square, triangle, semicircle or hexagon (default square).

use hw_sim::camera::{depth_to_gray, flow_to_rgb};
use hw_sim::{CameraFrame, World, WorldConfig};
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(args.next().unwrap_or_else(|| "frames".into()));
    let mut config = WorldConfig::default();
    if let Some(peg) = args.next() {
        config.task.peg = WorldConfig::from_toml(&format!("[task]\npeg = \"{peg}\""))?
            .task
            .peg;
    }
    std::fs::create_dir_all(&out)?;
    let mut world = World::new(config)?;
    let model = world.model().clone();
    let mut data = model.create_data();
    let q0 = world.q().to_vec();
    let mut frame = CameraFrame::default();
    let mut written = 0;
    // Joint-space PD around a slow sinusoid of joints 1 and 2: enough motion
    // for a visible flow field.
    while written < 6 {
        let t = world.time_s();
        let q_ref: Vec<f64> = q0
            .iter()
            .enumerate()
            .map(|(k, q)| q + if k < 2 { 0.25 * (2.0 * t).sin() } else { 0.0 })
            .collect();
        let g = robot_model::gravity(&model, &mut data, world.q()).clone();
        let tau: Vec<f64> = (0..q0.len())
            .map(|k| g[k] + 400.0 * (q_ref[k] - world.q()[k]) - 40.0 * world.v()[k])
            .collect();
        world.step(&tau)?;
        if world.camera_due() {
            world.render(&mut frame);
            if frame.index >= 4 && frame.index % 4 == 0 {
                let (w, h) = (frame.width, frame.height);
                let stem = out.join(format!("frame_{:03}", frame.index));
                hw_sim::png::write(stem.with_extension("rgb.png"), w, h, 3, &frame.rgb)?;
                let depth = depth_to_gray(&frame, 0.5, 2.5);
                hw_sim::png::write(stem.with_extension("depth.png"), w, h, 1, &depth)?;
                let flow = flow_to_rgb(&frame, 3.0);
                hw_sim::png::write(stem.with_extension("flow.png"), w, h, 3, &flow)?;
                written += 1;
            }
        }
    }
    println!(
        "wrote {written} frames (rgb, depth, flow) to {}",
        out.display()
    );
    Ok(())
}
