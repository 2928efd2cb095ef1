//! The contact sheet of `learner dataset inspect`.

use super::*;
use std::path::Path;

/// A contact sheet: for `n` samples, a row of RGB, depth, flow and mask.
pub fn contact_sheet(ds: &Dataset, n: usize, path: &Path) -> Result<()> {
    let (w, h) = (ds.meta.width, ds.meta.height);
    let ids: Vec<u64> = (0..n as u64)
        .map(|k| k * ds.len() / n.max(1) as u64)
        .filter(|&id| id < ds.len())
        .collect();
    let cols = 4;
    let (sw, sh) = (cols * w, ids.len() * h);
    let mut img = vec![255u8; sw * sh * 3];
    for (row, &id) in ids.iter().enumerate() {
        let (shard, block) = locate(ds, id)?;
        let samples = ds.read_block(shard, block)?;
        let first = ds.meta.shards[shard].1[block].first_id;
        let s = &samples[(id - first) as usize];
        let mut frame = hw_sim::CameraFrame {
            width: w as u32,
            height: h as u32,
            depth_m: s.depth.clone(),
            flow_px: s.flow.chunks_exact(2).map(|f| [f[0], f[1]]).collect(),
            flow_mask: s.mask.clone(),
            ..Default::default()
        };
        frame.rgb = s.rgb.clone();
        let depth = hw_sim::camera::depth_to_gray(&frame, 0.3, 2.5);
        let flow = hw_sim::camera::flow_to_rgb(&frame, 2.0);
        for y in 0..h {
            for x in 0..w {
                let i = y * w + x;
                let d = depth[i];
                let m = if s.mask[i] == 1 { 255 } else { 0 };
                let tiles = [
                    [s.rgb[3 * i], s.rgb[3 * i + 1], s.rgb[3 * i + 2]],
                    [d, d, d],
                    [flow[3 * i], flow[3 * i + 1], flow[3 * i + 2]],
                    [m, m, if s.contact_next { 0 } else { m }],
                ];
                for (c, px) in tiles.iter().enumerate() {
                    let o = ((row * h + y) * sw + c * w + x) * 3;
                    img[o..o + 3].copy_from_slice(px);
                }
            }
        }
    }
    stack_common::png::write(path, sw as u32, sh as u32, 3, &img).map_err(|source| {
        DatasetError::Sheet {
            path: path.to_path_buf(),
            source,
        }
    })
}

pub(super) fn locate(ds: &Dataset, id: u64) -> Result<(usize, usize)> {
    for (s, (_, blocks)) in ds.meta.shards.iter().enumerate() {
        for (k, b) in blocks.iter().enumerate() {
            if id >= b.first_id && id < b.first_id + b.samples as u64 {
                return Ok((s, k));
            }
        }
    }
    Err(DatasetError::NoSuchSample(id))
}
