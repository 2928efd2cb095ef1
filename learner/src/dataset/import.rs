//! `learner dataset import`: the authors' published HDF5 episodes (Lee et
//! al.'s multimodal_representation repository, `triangle_real_data`: one
//! file per episode) into this dataset format, labelled as the authors'
//! loader (`MultimodalManipulationDataset.py`) labels them.
//!
//! Per file, T steps (50 in their data) of `image {T,H,W,3}` u8,
//! `depth_data {T,H,W,1}`, `optical_flow {T,H,W,2}`, `ee_forces_continuous
//! {T,R,6}` (R ≥ 32 readings per step), `contact {T,K}`, `proprio {T,8}`,
//! `action {T,4}` and `ee_pos {T,3}`; the other keys of their layout are
//! not needed and not read. Step t (0 ≤ t < T − 1) becomes one sample: the
//! image, depth and flow of step t, the newest 32 force readings of step t,
//! the 8 proprioception values as recorded (the paper's), the next step's
//! action, contact now and next as any non-zero reading of steps t and
//! t + 1, the flow mask where the flow's two channels do not sum to zero
//! (their rule), and `ee_next` the next step's first four proprioception
//! values (their end-effector label). What their data has no counterpart
//! for: the stage (a lower bound: touched from the first contact on), the
//! policy (`imported`) and the camera (none recorded).

use super::balance::{MOVING_M, SampleTags};
use super::build::Builder;
use super::{BuildConfig, DatasetError, EpisodeSamples, Meta, PROPRIO, Result, Sample};
use hw_sim::PegShape;
use learner_node::mix::EpisodePolicy;
use learner_node::policy::WRENCH_WINDOW;
use rust_hdf5::{ByteOrder, DatatypeMessage, H5Dataset, H5File};
use shared_mem_schema::Stage;
use std::path::{Path, PathBuf};

/// One key's values, widened to f32, and its shape.
struct Field {
    shape: Vec<usize>,
    values: Vec<f32>,
}

/// An import failure inside one file: the key, what was expected and what
/// was found.
fn bad(
    file: &Path,
    key: &str,
    expected: impl Into<String>,
    found: impl Into<String>,
) -> DatasetError {
    DatasetError::Import {
        file: file.to_path_buf(),
        key: key.into(),
        expected: expected.into(),
        found: found.into(),
    }
}

/// The element type's name, for errors.
fn type_name(dt: &DatatypeMessage) -> String {
    match dt {
        DatatypeMessage::FixedPoint { size, signed, .. } => {
            format!("{}{}", if *signed { "int" } else { "uint" }, 8 * size)
        }
        DatatypeMessage::FloatingPoint { size, .. } => format!("float{}", 8 * size),
        DatatypeMessage::Enum { base, .. } => format!("enum of {}", type_name(base)),
        other => format!("{other:?}").chars().take(40).collect(),
    }
}

/// `key`'s dataset in `file` and its element type as declared.
fn dataset(f: &H5File, file: &Path, key: &str) -> Result<(H5Dataset, DatatypeMessage)> {
    let ds = f
        .dataset(key)
        .map_err(|e| bad(file, key, "the key present", format!("{e:?}")))?;
    let dt = ds
        .datatype()
        .map_err(|e| bad(file, key, "a readable datatype", format!("{e:?}")))?;
    Ok((ds, dt))
}

/// Reads `key` from `file` as f32 values, any integer, boolean or float
/// element type, little-endian.
fn read(f: &H5File, file: &Path, key: &str) -> Result<Field> {
    let (ds, dt) = dataset(f, file, key)?;
    values(file, key, &ds, dt)
}

/// `ds`'s values (`key` of `file`, of element type `dt`) as f32.
fn values(file: &Path, key: &str, ds: &H5Dataset, dt: DatatypeMessage) -> Result<Field> {
    let shape = ds.shape();
    // Read whole, so bounded first: the authors' largest key holds 2.5 M
    // values; a header claiming more than 2²⁸ is not their layout.
    let count = shape.iter().try_fold(1usize, |n, &d| n.checked_mul(d));
    if count.is_none_or(|n| n > 1 << 28) {
        return Err(bad(
            file,
            key,
            "at most 2^28 values",
            format!("shape {shape:?}"),
        ));
    }
    let dt = match dt {
        DatatypeMessage::Enum { base, .. } => *base,
        d => d,
    };
    let err = |e: rust_hdf5::Hdf5Error| bad(file, key, "readable values", format!("{e:?}"));
    let values: Vec<f32> = match &dt {
        DatatypeMessage::FixedPoint {
            size,
            signed,
            byte_order: ByteOrder::LittleEndian,
            ..
        } => match (size, signed) {
            (1, false) => widened(ds, f32::from as fn(u8) -> f32),
            (1, true) => widened(ds, f32::from as fn(i8) -> f32),
            (2, false) => widened(ds, f32::from as fn(u16) -> f32),
            (2, true) => widened(ds, f32::from as fn(i16) -> f32),
            (4, false) => widened(ds, |x: u32| x as f32),
            (4, true) => widened(ds, |x: i32| x as f32),
            (8, false) => widened(ds, |x: u64| x as f32),
            (8, true) => widened(ds, |x: i64| x as f32),
            _ => return Err(bad(file, key, "a number type", type_name(&dt))),
        },
        DatatypeMessage::FloatingPoint {
            size: 4,
            byte_order: ByteOrder::LittleEndian,
            ..
        } => ds.read_raw::<f32>(),
        DatatypeMessage::FloatingPoint {
            size: 8,
            byte_order: ByteOrder::LittleEndian,
            ..
        } => widened(ds, |x: f64| x as f32),
        _ => {
            return Err(bad(
                file,
                key,
                "a little-endian number type",
                type_name(&dt),
            ));
        }
    }
    .map_err(err)?;
    if Some(values.len()) != count {
        return Err(bad(
            file,
            key,
            format!("{} values for shape {shape:?}", count.unwrap_or(0)),
            format!("{}", values.len()),
        ));
    }
    Ok(Field { shape, values })
}

/// The dataset's values read as `T` and widened to f32 by `to_f32`.
fn widened<T: rust_hdf5::types::H5Type>(
    ds: &H5Dataset,
    to_f32: impl Fn(T) -> f32,
) -> rust_hdf5::Result<Vec<f32>> {
    Ok(ds.read_raw::<T>()?.into_iter().map(to_f32).collect())
}

/// Checks `field`'s shape against `expected` (`None`: any size there).
fn check_shape(file: &Path, key: &str, field: &Field, expected: &[Option<usize>]) -> Result<()> {
    let fits = field.shape.len() == expected.len()
        && field
            .shape
            .iter()
            .zip(expected)
            .all(|(n, e)| e.is_none_or(|e| *n == e));
    if fits {
        return Ok(());
    }
    let want: Vec<String> = expected
        .iter()
        .map(|e| e.map_or("any".to_string(), |n| n.to_string()))
        .collect();
    Err(bad(
        file,
        key,
        format!("shape [{}]", want.join(", ")),
        format!("shape {:?}", field.shape),
    ))
}

/// The samples of one of the authors' files.
pub fn import_file(file: &Path, peg: PegShape) -> Result<EpisodeSamples> {
    let f =
        H5File::open(file).map_err(|e| bad(file, "(file)", "an HDF5 file", format!("{e:?}")))?;
    let (image_ds, image_type) = dataset(&f, file, "image")?;
    if !matches!(
        image_type,
        DatatypeMessage::FixedPoint {
            size: 1,
            signed: false,
            ..
        }
    ) {
        return Err(bad(file, "image", "uint8", type_name(&image_type)));
    }
    let image = values(file, "image", &image_ds, image_type)?;
    let (t, h, w) = match image.shape[..] {
        [t, h, w, 3] if t >= 2 && h > 0 && w > 0 => (t, h, w),
        _ => {
            return Err(bad(
                file,
                "image",
                "shape [T ≥ 2, H, W, 3]",
                format!("shape {:?}", image.shape),
            ));
        }
    };
    let (t_, h_, w_) = (Some(t), Some(h), Some(w));
    let depth = read(&f, file, "depth_data")?;
    check_shape(file, "depth_data", &depth, &[t_, h_, w_, Some(1)])?;
    let flow = read(&f, file, "optical_flow")?;
    check_shape(file, "optical_flow", &flow, &[t_, h_, w_, Some(2)])?;
    let forces = read(&f, file, "ee_forces_continuous")?;
    check_shape(file, "ee_forces_continuous", &forces, &[t_, None, Some(6)])?;
    let readings = forces.shape[1];
    if readings < WRENCH_WINDOW {
        return Err(bad(
            file,
            "ee_forces_continuous",
            format!("at least {WRENCH_WINDOW} readings per step"),
            format!("{readings}"),
        ));
    }
    let contact = read(&f, file, "contact")?;
    check_shape(file, "contact", &contact, &[t_, None])?;
    let proprio = read(&f, file, "proprio")?;
    check_shape(file, "proprio", &proprio, &[t_, Some(PROPRIO)])?;
    let action = read(&f, file, "action")?;
    check_shape(file, "action", &action, &[t_, Some(4)])?;
    let ee_pos = read(&f, file, "ee_pos")?;
    check_shape(file, "ee_pos", &ee_pos, &[t_, Some(3)])?;
    for (key, field) in [
        ("depth_data", &depth),
        ("optical_flow", &flow),
        ("ee_forces_continuous", &forces),
        ("contact", &contact),
        ("proprio", &proprio),
        ("action", &action),
        ("ee_pos", &ee_pos),
    ] {
        if let Some(i) = field.values.iter().position(|x| !x.is_finite()) {
            return Err(bad(
                file,
                key,
                "finite values",
                format!("{} at element {i}", field.values[i]),
            ));
        }
    }

    let n = h * w;
    let k = contact.shape[1];
    let in_contact = |s: usize| contact.values[s * k..(s + 1) * k].iter().any(|&c| c != 0.0);
    let row = |field: &Field, s: usize, width: usize| -> Vec<f32> {
        field.values[s * width..(s + 1) * width].to_vec()
    };
    let mut samples = Vec::with_capacity(t - 1);
    let mut tags = Vec::with_capacity(t - 1);
    let mut touched = false;
    for s in 0..t - 1 {
        let contact_now = in_contact(s);
        touched |= contact_now;
        let window =
            &forces.values[(s * readings + readings - WRENCH_WINDOW) * 6..(s + 1) * readings * 6];
        let flow_s = row(&flow, s, 2 * n);
        let mask: Vec<u8> = flow_s
            .chunks_exact(2)
            .map(|v| u8::from(v[0] + v[1] != 0.0))
            .collect();
        let next = row(&proprio, s + 1, PROPRIO);
        let moved = (0..3)
            .map(|i| (ee_pos.values[(s + 1) * 3 + i] - ee_pos.values[s * 3 + i]).powi(2))
            .sum::<f32>()
            .sqrt();
        let stage = if touched {
            Stage::Touched
        } else {
            Stage::Failed
        };
        samples.push(Sample {
            episode: 0,
            index: s as u32,
            step: s as u64,
            contact: contact_now,
            contact_next: in_contact(s + 1),
            stage,
            rgb: image.values[s * 3 * n..(s + 1) * 3 * n]
                .iter()
                .map(|&v| v as u8)
                .collect(),
            depth: row(&depth, s, n),
            wrench: window.to_vec(),
            proprio: row(&proprio, s, PROPRIO).try_into().expect("8 values"),
            action: row(&action, s + 1, 4).try_into().expect("4 values"),
            flow: flow_s,
            mask,
            ee_next: next[..4].try_into().expect("4 values"),
        });
        tags.push(SampleTags {
            stage,
            moving: f64::from(moved) > MOVING_M,
        });
    }
    Ok(EpisodeSamples {
        peg,
        policy: EpisodePolicy::Imported,
        samples,
        tags,
        size: (w, h),
        camera: None,
    })
}

/// The `.h5` and `.hdf5` files under `inputs` (files or directories),
/// sorted.
pub fn find_hdf5(inputs: &[PathBuf]) -> Result<Vec<PathBuf>> {
    let is_h5 = |p: &Path| {
        p.extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("h5") || e.eq_ignore_ascii_case("hdf5"))
    };
    let mut out = Vec::new();
    for p in inputs {
        if p.is_dir() {
            let entries = std::fs::read_dir(p).map_err(|source| DatasetError::Io {
                path: p.clone(),
                source,
            })?;
            out.extend(
                entries
                    .filter_map(|e| e.ok().map(|e| e.path()))
                    .filter(|p| is_h5(p)),
            );
        } else if p.exists() {
            out.push(p.clone());
        } else {
            return Err(DatasetError::NoInput(p.clone()));
        }
    }
    out.sort();
    Ok(out)
}

/// Imports `files` (in order) into a dataset in `out`. A file that differs
/// from the layout ends the import with an error naming it, the key, what
/// was expected and what was found: nothing half-labelled is written.
pub fn import(
    files: &[PathBuf],
    out: &Path,
    peg: PegShape,
    cfg: &BuildConfig,
    mut on_file: impl FnMut(&Path, usize),
) -> Result<Meta> {
    let mut b = Builder::new(out, cfg)?;
    for file in files {
        let ep = import_file(file, peg)?;
        let n = ep.samples.len();
        b.add_episode(file, ep)?;
        on_file(file, n);
    }
    b.finish()
}
