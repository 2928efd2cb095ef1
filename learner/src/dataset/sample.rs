//! One sample and its byte encoding inside a block.

use super::*;
use learner_node::policy::WRENCH_WINDOW;

/// One sample.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Sample {
    /// Episode (dataset-wide number).
    pub episode: u32,
    /// Index within the episode.
    pub index: u32,
    /// Hardware step of the frame.
    pub step: u64,
    /// Contact now.
    pub contact: bool,
    /// Label: contact at the next step.
    pub contact_next: bool,
    /// The best task stage the episode had reached by this frame (format 4;
    /// for people and evaluation, not an input).
    pub stage: shared_mem_schema::Stage,
    /// RGB, H×W×3.
    pub rgb: Vec<u8>,
    /// Depth, m, H×W.
    pub depth: Vec<f32>,
    /// Wrench window, oldest first, 32×6.
    pub wrench: Vec<f32>,
    /// Proprioception ([`PROPRIO`]).
    pub proprio: [f32; PROPRIO],
    /// The next action (Δx, Δy, Δz, Δroll).
    pub action: [f32; 4],
    /// Label: flow, H×W×2, px.
    pub flow: Vec<f32>,
    /// Label: flow mask, H×W.
    pub mask: Vec<u8>,
    /// Label: the end-effector's position (m) and roll (rad, the episode's
    /// reference, as in `proprio[3]`) at the next step: the next sample's
    /// first four proprioception values (format 5; position only before).
    pub ee_next: [f32; 4],
}

pub(super) fn sample_bytes(w: usize, h: usize) -> usize {
    let n = w * h;
    24 + 3 * n + 4 * n + 4 * WRENCH_WINDOW * 6 + 4 * PROPRIO + 16 + 8 * n + n + 16
}

pub(super) fn put_f32s(out: &mut Vec<u8>, xs: &[f32]) {
    for x in xs {
        out.extend_from_slice(&x.to_le_bytes());
    }
}

pub(super) fn get_f32s(buf: &[u8], at: &mut usize, out: &mut [f32]) {
    for x in out.iter_mut() {
        *x = f32::from_le_bytes(buf[*at..*at + 4].try_into().expect("4 bytes"));
        *at += 4;
    }
}

impl Sample {
    pub(super) fn encode(&self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.episode.to_le_bytes());
        out.extend_from_slice(&self.index.to_le_bytes());
        out.extend_from_slice(&self.step.to_le_bytes());
        out.extend_from_slice(&[
            self.contact as u8,
            self.contact_next as u8,
            self.stage.code() as u8,
            0,
            0,
            0,
            0,
            0,
        ]);
        out.extend_from_slice(&self.rgb);
        put_f32s(out, &self.depth);
        put_f32s(out, &self.wrench);
        put_f32s(out, &self.proprio);
        put_f32s(out, &self.action);
        put_f32s(out, &self.flow);
        out.extend_from_slice(&self.mask);
        put_f32s(out, &self.ee_next);
    }

    pub(super) fn decode(buf: &[u8], w: usize, h: usize) -> Self {
        let n = w * h;
        let u32_at = |a: usize| u32::from_le_bytes(buf[a..a + 4].try_into().expect("4"));
        let mut s = Sample {
            episode: u32_at(0),
            index: u32_at(4),
            step: u64::from_le_bytes(buf[8..16].try_into().expect("8")),
            contact: buf[16] != 0,
            contact_next: buf[17] != 0,
            stage: shared_mem_schema::Stage::from_code(buf[18] as u32),
            rgb: buf[24..24 + 3 * n].to_vec(),
            depth: vec![0.0; n],
            wrench: vec![0.0; WRENCH_WINDOW * 6],
            flow: vec![0.0; 2 * n],
            ..Default::default()
        };
        let mut at = 24 + 3 * n;
        get_f32s(buf, &mut at, &mut s.depth);
        get_f32s(buf, &mut at, &mut s.wrench);
        get_f32s(buf, &mut at, &mut s.proprio);
        get_f32s(buf, &mut at, &mut s.action);
        get_f32s(buf, &mut at, &mut s.flow);
        s.mask = buf[at..at + n].to_vec();
        at += n;
        get_f32s(buf, &mut at, &mut s.ee_next);
        s
    }
}
