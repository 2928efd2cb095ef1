//! The encoder's weights file (`encoder.bin`): a trained representation as
//! the node runs it, readable without burn.
//!
//! Layout: the 8 bytes `LNENC001`; the header's length in bytes (u64, little
//! endian); the header, JSON ([`Header`]: the model's sizes, its input
//! normaliser, active sensors and camera, and the list of arrays with their
//! shapes); then every array's values in that order, f32 little endian,
//! row-major. Array names and shapes are those of [`EncoderWeights`]:
//! `rgb.conv0.weight` `[k·k·cin, cout]` (rows in (ky, kx, ci) order),
//! `rgb.conv0.bias` `[cout]`, `rgb.fc.weight` `[in, 2d]` (rows channels-last),
//! `haptics.layer0.weight` `[2·cin, cout]`, `proprio.layer0.weight`,
//! `concat.layer0.weight` `[in, out]`, each with its `.bias`.

use super::Modalities;
use super::fast::{Conv, Dense, EncoderWeights, ImageEncoder, WeightsError, WrenchStack};
use super::inputs::Normaliser;
use serde::{Deserialize, Serialize};
use shared_mem_schema::CameraCalibration;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// The file's first bytes (format version 1).
pub const MAGIC: &[u8; 8] = b"LNENC001";

/// A weights file that could not be read or written.
#[derive(Debug, thiserror::Error)]
#[error("{}: {kind}", path.display())]
pub struct FileError {
    /// The file.
    pub path: PathBuf,
    /// Why.
    pub kind: FileErrorKind,
}

/// What went wrong with a file.
#[derive(Debug, thiserror::Error)]
pub enum FileErrorKind {
    /// Reading or writing it failed.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// Its contents are not a usable model.
    #[error(transparent)]
    Weights(#[from] WeightsError),
}

/// One convolution's settings (its sizes are its arrays').
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ConvSpec {
    /// Kernel side.
    pub kernel: usize,
    /// Stride.
    pub stride: usize,
    /// Zero padding on every side.
    pub padding: usize,
}

/// An array's name and shape.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArraySpec {
    /// Its name (see the module's documentation).
    pub name: String,
    /// Its shape.
    pub shape: Vec<usize>,
}

/// The JSON header of a weights file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Header {
    /// Latent size d.
    pub latent_dim: usize,
    /// Image side the model takes, px.
    pub image_side: usize,
    /// The leaky ReLU's slope for negative inputs.
    pub leaky_slope: f32,
    /// Added to every expert's variance.
    pub min_variance: f32,
    /// The sensors the encoding uses.
    pub modalities: Modalities,
    /// The inputs' normalisation (the training dataset's statistics).
    pub normaliser: Normaliser,
    /// The camera of its training images, when known.
    pub camera: Option<CameraCalibration>,
    /// The RGB encoder's convolutions (`None`: no RGB encoder).
    pub rgb: Option<Vec<ConvSpec>>,
    /// The depth encoder's convolutions.
    pub depth: Option<Vec<ConvSpec>>,
    /// The arrays, in the order of their values.
    pub arrays: Vec<ArraySpec>,
}

/// A trained representation for inference: its weights and what its
/// inputs need.
#[derive(Debug, Clone, PartialEq)]
pub struct EncoderFile {
    /// The layers.
    pub weights: EncoderWeights,
    /// The sensors the encoding uses.
    pub modalities: Modalities,
    /// The inputs' normalisation.
    pub normaliser: Normaliser,
    /// The camera of its training images, when known.
    pub camera: Option<CameraCalibration>,
}

fn push_dense(out: &mut Vec<(String, Vec<usize>, Vec<f32>)>, name: &str, l: &Dense) {
    out.push((format!("{name}.weight"), vec![l.n_in, l.n_out], l.w.clone()));
    out.push((format!("{name}.bias"), vec![l.n_out], l.b.clone()));
}

fn push_image(out: &mut Vec<(String, Vec<usize>, Vec<f32>)>, name: &str, e: &ImageEncoder) {
    for (i, c) in e.convs.iter().enumerate() {
        out.push((
            format!("{name}.conv{i}.weight"),
            vec![c.k * c.k * c.cin, c.cout],
            c.w.clone(),
        ));
        out.push((format!("{name}.conv{i}.bias"), vec![c.cout], c.b.clone()));
    }
    push_dense(out, &format!("{name}.fc"), &e.fc);
}

fn conv_specs(e: &ImageEncoder) -> Vec<ConvSpec> {
    e.convs
        .iter()
        .map(|c| ConvSpec {
            kernel: c.k,
            stride: c.stride,
            padding: c.pad,
        })
        .collect()
}

/// The arrays of a file, by name, each taken once.
struct Arrays(HashMap<String, (Vec<usize>, Vec<f32>)>);

impl Arrays {
    fn take(&mut self, name: &str) -> Result<(Vec<usize>, Vec<f32>), WeightsError> {
        self.0
            .remove(name)
            .ok_or_else(|| WeightsError::Missing(name.into()))
    }

    fn has(&self, name: &str) -> bool {
        self.0.contains_key(name)
    }

    /// A fully connected layer `name` (a 2-D weight, a 1-D bias).
    fn dense(&mut self, name: &str) -> Result<Dense, WeightsError> {
        let (ws, w) = self.take(&format!("{name}.weight"))?;
        let [n_in, n_out] = ws[..] else {
            return Err(WeightsError::Format(format!(
                "array {name}.weight: {} dimensions, expected 2",
                ws.len()
            )));
        };
        let (_, b) = self.take(&format!("{name}.bias"))?;
        Ok(Dense { w, b, n_in, n_out })
    }

    /// Layers `name.layer0`, `name.layer1`… while the file has them.
    fn layers(&mut self, name: &str) -> Result<Option<Vec<Dense>>, WeightsError> {
        let mut v = Vec::new();
        while self.has(&format!("{name}.layer{}.weight", v.len())) {
            v.push(self.dense(&format!("{name}.layer{}", v.len()))?);
        }
        Ok((!v.is_empty()).then_some(v))
    }

    fn image(&mut self, name: &str, specs: &[ConvSpec]) -> Result<ImageEncoder, WeightsError> {
        let mut convs = Vec::new();
        for (i, s) in specs.iter().enumerate() {
            let (ws, w) = self.take(&format!("{name}.conv{i}.weight"))?;
            let kk = s.kernel * s.kernel;
            let [rows, cout] = ws[..] else {
                return Err(WeightsError::Format(format!(
                    "array {name}.conv{i}.weight: {} dimensions, expected 2",
                    ws.len()
                )));
            };
            if kk == 0 || rows % kk != 0 {
                return Err(WeightsError::Format(format!(
                    "array {name}.conv{i}.weight: {rows} rows is no multiple of the kernel's \
                     {kk} taps"
                )));
            }
            let (_, b) = self.take(&format!("{name}.conv{i}.bias"))?;
            convs.push(Conv {
                k: s.kernel,
                stride: s.stride,
                pad: s.padding,
                cin: rows / kk,
                cout,
                w,
                b,
            });
        }
        let fc = self.dense(&format!("{name}.fc"))?;
        Ok(ImageEncoder { convs, fc })
    }
}

impl EncoderFile {
    /// The file's bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let w = &self.weights;
        let mut arrays = Vec::new();
        if let Some(e) = &w.rgb {
            push_image(&mut arrays, "rgb", e);
        }
        if let Some(e) = &w.depth {
            push_image(&mut arrays, "depth", e);
        }
        for (name, layers) in [
            ("haptics", w.haptics.as_ref().map(|h| &h.0)),
            ("proprio", w.proprio.as_ref()),
            ("concat", w.concat.as_ref()),
        ] {
            for (i, l) in layers.into_iter().flatten().enumerate() {
                push_dense(&mut arrays, &format!("{name}.layer{i}"), l);
            }
        }
        let header = Header {
            latent_dim: w.latent_dim,
            image_side: w.image_side,
            leaky_slope: w.leaky_slope,
            min_variance: w.min_variance,
            modalities: self.modalities,
            normaliser: self.normaliser.clone(),
            camera: self.camera,
            rgb: w.rgb.as_ref().map(conv_specs),
            depth: w.depth.as_ref().map(conv_specs),
            arrays: arrays
                .iter()
                .map(|(name, shape, _)| ArraySpec {
                    name: name.clone(),
                    shape: shape.clone(),
                })
                .collect(),
        };
        let json = serde_json::to_vec(&header).expect("a header serialises");
        let mut out = Vec::with_capacity(16 + json.len());
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&(json.len() as u64).to_le_bytes());
        out.extend_from_slice(&json);
        for (_, _, values) in &arrays {
            for v in values {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
        out
    }

    /// From a file's bytes; every size checked.
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, WeightsError> {
        if bytes.len() < 16 || &bytes[..8] != MAGIC {
            return Err(WeightsError::Format(format!(
                "not an encoder weights file (it does not start with {:?})",
                std::str::from_utf8(MAGIC).unwrap_or_default()
            )));
        }
        let n = u64::from_le_bytes(bytes[8..16].try_into().expect("8 bytes"));
        let rest = &bytes[16..];
        if n > rest.len() as u64 {
            return Err(WeightsError::Format(format!(
                "truncated: the header takes {n} bytes, the file holds {} after its length",
                rest.len()
            )));
        }
        let (json, mut values) = rest.split_at(n as usize);
        let h: Header = serde_json::from_slice(json)
            .map_err(|e| WeightsError::Format(format!("header: {e}")))?;
        let expected: u64 = h
            .arrays
            .iter()
            .map(|a| 4 * a.shape.iter().map(|&s| s as u64).product::<u64>())
            .sum();
        if expected != values.len() as u64 {
            return Err(WeightsError::Truncated {
                expected,
                found: values.len() as u64,
            });
        }
        let mut map = HashMap::new();
        for a in &h.arrays {
            let len: usize = a.shape.iter().product();
            let (these, after) = values.split_at(4 * len);
            values = after;
            let data = these
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect();
            if map
                .insert(a.name.clone(), (a.shape.clone(), data))
                .is_some()
            {
                return Err(WeightsError::Format(format!(
                    "array {} named twice",
                    a.name
                )));
            }
        }
        let mut arrays = Arrays(map);
        let weights = EncoderWeights {
            latent_dim: h.latent_dim,
            image_side: h.image_side,
            leaky_slope: h.leaky_slope,
            min_variance: h.min_variance,
            rgb: h
                .rgb
                .as_deref()
                .map(|s| arrays.image("rgb", s))
                .transpose()?,
            depth: h
                .depth
                .as_deref()
                .map(|s| arrays.image("depth", s))
                .transpose()?,
            haptics: arrays.layers("haptics")?.map(WrenchStack),
            proprio: arrays.layers("proprio")?,
            concat: arrays.layers("concat")?,
        };
        if let Some(name) = arrays.0.keys().min() {
            return Err(WeightsError::Format(format!(
                "array {name} belongs to no layer of the header's model"
            )));
        }
        weights.check()?;
        h.normaliser.validate().map_err(WeightsError::Format)?;
        Ok(Self {
            weights,
            modalities: h.modalities,
            normaliser: h.normaliser,
            camera: h.camera,
        })
    }

    /// Reads `path`.
    pub fn read(path: &Path) -> Result<Self, FileError> {
        let err = |kind: FileErrorKind| FileError {
            path: path.to_path_buf(),
            kind,
        };
        let bytes = std::fs::read(path).map_err(|e| err(e.into()))?;
        Self::from_bytes(&bytes).map_err(|e| err(e.into()))
    }

    /// Writes `path`.
    pub fn write(&self, path: &Path) -> Result<(), FileError> {
        std::fs::write(path, self.to_bytes()).map_err(|e| FileError {
            path: path.to_path_buf(),
            kind: e.into(),
        })
    }
}
