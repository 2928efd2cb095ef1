//! Log → samples: one log's frames, actions and camera images turned into
//! labelled samples.

use super::*;
use crate::labels::{FlowLabeler, in_contact};
use hw_sim::PegShape;
use learner_node::log::{CameraImage, Event, LogReader, topics};
use learner_node::mix::EpisodePolicy;
use learner_node::policy::WRENCH_WINDOW;
use learner_node::proprio::{Proprio, roll_reference};
use robot_model::descriptions::RobotCatalog;
use serde::{Deserialize, Serialize};
use shared_mem_schema::{CameraCalibration, PolicyAction, SensorFrame, Stage};
use std::collections::HashMap;
use std::path::Path;

/// How labels are made.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct BuildConfig {
    /// Contact: mean force change against free space above this, N.
    pub contact_threshold_n: f64,
    /// Readings averaged for the contact test.
    pub contact_window: usize,
    /// Flow mask: rendered robot depth within this of the recorded depth, m.
    pub flow_depth_tol_m: f64,
    /// Flow mask: image motion from which a robot pixel counts as moving, px
    /// (0: every robot pixel, as format version 1).
    pub flow_mask_min_px: f64,
    /// Samples per compressed block (the loader's unit of reading).
    pub block_samples: usize,
    /// Samples per shard file.
    pub shard_samples: usize,
    /// zstd level.
    pub zstd_level: i32,
    /// Directory of the URDF files logs may name as their robot (by a
    /// relative path inside it); `None`: built-in robots only. A log never
    /// makes the builder read a file outside it.
    pub robot_dir: Option<std::path::PathBuf>,
}

impl Default for BuildConfig {
    fn default() -> Self {
        Self {
            contact_threshold_n: 3.0,
            contact_window: 4,
            flow_depth_tol_m: 0.01,
            flow_mask_min_px: hw_sim::camera::FLOW_MASK_MIN_PX as f64,
            block_samples: 32,
            shard_samples: 4096,
            zstd_level: 3,
            robot_dir: None,
        }
    }
}

/// The samples of one log.
pub struct EpisodeSamples {
    /// Peg.
    pub peg: PegShape,
    /// Policy.
    pub policy: EpisodePolicy,
    /// Samples in order.
    pub samples: Vec<Sample>,
    /// Per sample: the stage reached and whether it moves (the balance).
    pub tags: Vec<SampleTags>,
    /// Image size.
    pub size: (usize, usize),
    /// The camera's calibration (the same for every frame of the episode);
    /// `None` when the log gave no sample.
    pub camera: Option<CameraCalibration>,
}

/// Models by robot name, loaded once, from the robots a catalog allows
/// (default: the built-in ones).
#[derive(Default)]
pub struct Models {
    robots: RobotCatalog,
    loaded: HashMap<String, robot_model::Model>,
}

impl Models {
    /// Robots are loaded from `robots`.
    pub fn new(robots: RobotCatalog) -> Self {
        Self {
            robots,
            loaded: HashMap::new(),
        }
    }

    pub(super) fn get(
        &mut self,
        robot: &str,
    ) -> Result<robot_model::Model, robot_model::ModelError> {
        if let Some(m) = self.loaded.get(robot) {
            return Ok(m.clone());
        }
        let m = self.robots.load(robot)?;
        self.loaded.insert(robot.into(), m.clone());
        Ok(m)
    }
}

/// Turns one log into samples with labels.
pub fn episode_samples(
    path: &Path,
    cfg: &BuildConfig,
    models: &mut Models,
) -> Result<EpisodeSamples> {
    let r = LogReader::open(path)?;
    let config = r
        .read_config(None)?
        .into_iter()
        .next()
        .ok_or_else(|| DatasetError::NoConfig(path.to_path_buf()))?
        .1;
    let world = &config.world;
    let model = models
        .get(&world.robot)
        .map_err(|source| DatasetError::Robot {
            log: path.to_path_buf(),
            robot: world.robot.clone(),
            source: Box::new(source),
        })?;
    let events = r.read_events(None)?;
    // A collection episode that a stop cut short is run again by a resumed
    // collection, or left out of it; its partial log is not data (checked
    // before its frames and images are decoded).
    if events
        .iter()
        .any(|(_, e)| matches!(e, Event::Outcome(o) if o.interrupted == Some(true)))
    {
        return Err(DatasetError::Interrupted(path.to_path_buf()));
    }
    let frames: Vec<SensorFrame> = r.read_raw(topics::SENSOR, None)?;
    let actions: Vec<PolicyAction> = r.read_raw(topics::ACTION, None)?;
    let cams: Vec<CameraImage> = r.read_camera(None)?;
    // When each better stage was reached (log time = hardware time).
    let stage_times: Vec<(u64, Stage)> = events
        .into_iter()
        .filter_map(|(t, e)| match e {
            Event::Stage { stage } => Some((t, stage)),
            _ => None,
        })
        .collect();
    let stage_at = |t: u64| {
        stage_times
            .iter()
            .filter(|(ts, _)| *ts <= t)
            .map(|(_, s)| *s)
            .max()
            .unwrap_or(Stage::Failed)
    };
    let mut tags = Vec::new();
    if frames.is_empty() {
        return Err(DatasetError::NoSensorFrames(path.to_path_buf()));
    }
    // Every frame indexes its joint arrays with its own count: it must be
    // the robot's, and fit the message.
    let fits = model.nv() <= shared_mem_schema::MAX_JOINTS;
    if let Some(f) = frames
        .iter()
        .find(|f| !fits || f.n_joints as usize != model.nv())
    {
        return Err(DatasetError::JointCount {
            log: path.to_path_buf(),
            step: f.step,
            n_joints: f.n_joints,
            robot: world.robot.clone(),
            model: model.nv(),
        });
    }
    let by_time: HashMap<u64, usize> = frames
        .iter()
        .enumerate()
        .map(|(i, f)| (f.header.t_hw_ns, i))
        .collect();
    let by_seq: HashMap<u64, &PolicyAction> = actions.iter().map(|a| (a.header.seq, a)).collect();
    let force = |i: usize| {
        let w = &frames[i].wrench;
        [w[0], w[1], w[2]]
    };
    // Free space: the episode starts away from the box.
    let first: Vec<[f64; 3]> = (0..frames.len().min(WRENCH_WINDOW)).map(force).collect();
    let mut free = [0.0; 3];
    for f in &first {
        for k in 0..3 {
            free[k] += f[k] / first.len() as f64;
        }
    }
    let contact_at = |i: usize| {
        let lo = (i + 1).saturating_sub(cfg.contact_window);
        let fs: Vec<[f64; 3]> = (lo..=i).map(force).collect();
        in_contact(&fs, &free, cfg.contact_threshold_n)
    };
    // Roll is taken from the episode's start (a log holds one episode).
    let roll_ref = roll_reference(&frames[0]);
    let mut labeler: Option<FlowLabeler> = None;
    let mut out = Vec::new();
    let nq = frames[0].n_joints as usize;
    let mut camera: Option<CameraCalibration> = None;
    for pair in cams.windows(2) {
        let (c0, c1) = (&pair[0], &pair[1]);
        let (Some(&i0), Some(&i1)) = (
            by_time.get(&c0.header.t_hw_ns),
            by_time.get(&c1.header.t_hw_ns),
        ) else {
            continue; // a frame without its sensor frame (a lost message)
        };
        if i1 <= i0 || i0 == 0 {
            continue;
        }
        // The action taken in this interval: newest applied by its end, if
        // it was not already in force at its start.
        let (a_prev, a_new) = (frames[i0 - 1].action_seq, frames[i1 - 1].action_seq);
        if a_new == a_prev {
            continue;
        }
        let Some(a) = by_seq.get(&a_new) else {
            continue;
        };
        if labeler.is_none() {
            let cal = c0.calibration;
            labeler = Some(FlowLabeler::new(model.clone(), &world.task, &cal).map_err(
                |source| DatasetError::Labels {
                    log: path.to_path_buf(),
                    source: Box::new(source),
                },
            )?);
            camera = Some(cal);
        }
        // The labeler projects with the first frame's calibration.
        if camera.is_some_and(|c| !c.same_camera(&c0.calibration)) {
            return Err(DatasetError::CameraChanges(path.to_path_buf()));
        }
        let l = labeler.as_mut().expect("made");
        l.mask_min_px = cfg.flow_mask_min_px as f32;
        l.label(
            &frames[i0].q[..nq],
            &frames[i1].q[..nq],
            &c0.depth_m,
            cfg.flow_depth_tol_m,
        );
        let f0 = &frames[i0];
        let mut wrench = Vec::with_capacity(WRENCH_WINDOW * 6);
        for k in 0..WRENCH_WINDOW {
            let i = (i0 + k + 1).saturating_sub(WRENCH_WINDOW);
            wrench.extend(frames[i].wrench.iter().map(|&x| x as f32));
        }
        let proprio = Proprio::from_frame(f0, roll_ref).to_array();
        let ee1 = frames[i1].ee_pos_m;
        let roll1 = Proprio::from_frame(&frames[i1], roll_ref).roll_rad;
        let moved = (0..3)
            .map(|k| (ee1[k] - f0.ee_pos_m[k]).powi(2))
            .sum::<f64>()
            .sqrt();
        let stage = stage_at(f0.header.t_hw_ns);
        tags.push(SampleTags {
            stage,
            moving: moved > MOVING_M,
        });
        out.push(Sample {
            episode: 0,
            index: out.len() as u32,
            step: f0.step,
            contact: contact_at(i0),
            contact_next: contact_at(i1),
            stage,
            rgb: c0.rgb.clone(),
            depth: c0.depth_m.clone(),
            wrench,
            proprio,
            action: a.delta().map(|x| x as f32),
            flow: l.flow_px.iter().flat_map(|f| [f[0], f[1]]).collect(),
            mask: l.mask.clone(),
            ee_next: [ee1[0] as f32, ee1[1] as f32, ee1[2] as f32, roll1 as f32],
        });
    }
    Ok(EpisodeSamples {
        peg: world.task.peg,
        policy: config.policy,
        samples: out,
        tags,
        size: camera.map_or((0, 0), |c| (c.width as usize, c.height as usize)),
        camera,
    })
}
