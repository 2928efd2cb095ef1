//! Per-split metrics (the rows of the paper's appendix table of
//! representation losses), their CSV file and learning curves.

use crate::models::losses::Losses;
use crate::plot::{Chart, Series};
use burn::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Sums over the samples of a pass, turned into means by [`Metrics::row`].
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Samples seen.
    pub samples: u64,
    /// Of them time-aligned (the action-conditional losses are over these).
    pub paired: u64,
    /// Σ loss × its sample count, per term.
    sums: Terms,
    /// Contact predictions right (aligned samples).
    pub contact_right: u64,
    /// Contact labels that are 1 (aligned samples).
    pub contact_positive: u64,
    /// Pairing predictions right (all samples).
    pub pairing_right: u64,
    /// Batches with contact predictions (none: the model has no contact
    /// head).
    pub contact_batches: u64,
    /// Batches with a pairing loss (none: the model does not learn pairing).
    pub pairing_batches: u64,
    /// Aligned samples among all (pairing labels that are 1).
    pub pairing_positive: u64,
    /// Σ of the zero-flow baseline's endpoint error (aligned samples).
    #[serde(deserialize_with = "null_as_nan")]
    pub zero_flow_sum: f64,
}

/// Reads a JSON null (how serde_json writes NaN: a term the model lacks)
/// back as NaN.
fn null_as_nan<'de, D: serde::Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN))
}

/// One value per loss term (NaN: the model has no such term).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Terms {
    /// Weighted total.
    #[serde(deserialize_with = "null_as_nan")]
    pub total: f64,
    /// Flow endpoint error, px.
    #[serde(deserialize_with = "null_as_nan")]
    pub flow: f64,
    /// Flow-mask cross-entropy.
    #[serde(deserialize_with = "null_as_nan")]
    pub mask: f64,
    /// Contact cross-entropy.
    #[serde(deserialize_with = "null_as_nan")]
    pub contact: f64,
    /// Pairing cross-entropy.
    #[serde(deserialize_with = "null_as_nan")]
    pub pairing: f64,
    /// End-effector mean squared error, normalised.
    #[serde(deserialize_with = "null_as_nan")]
    pub ee: f64,
    /// KL to the prior.
    #[serde(deserialize_with = "null_as_nan")]
    pub kl: f64,
    /// Reconstruction: RGB.
    #[serde(deserialize_with = "null_as_nan")]
    pub recon_rgb: f64,
    /// Reconstruction: last wrench reading.
    #[serde(deserialize_with = "null_as_nan")]
    pub recon_wrench: f64,
    /// Reconstruction: proprioception.
    #[serde(deserialize_with = "null_as_nan")]
    pub recon_proprio: f64,
}

/// One row of the metrics table: means over a split.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Row {
    /// Epoch (1-based).
    pub epoch: u32,
    /// `train` or `test`.
    pub split: String,
    /// Samples.
    pub samples: u64,
    /// Mean losses (`NaN` where the model has no such term).
    pub loss: Terms,
    /// Contact accuracy on aligned samples.
    #[serde(deserialize_with = "null_as_nan")]
    pub contact_acc: f64,
    /// Pairing accuracy.
    #[serde(deserialize_with = "null_as_nan")]
    pub pairing_acc: f64,
    /// The majority class's contact accuracy.
    #[serde(deserialize_with = "null_as_nan")]
    pub contact_majority_acc: f64,
    /// The majority class's pairing accuracy.
    #[serde(deserialize_with = "null_as_nan")]
    pub pairing_majority_acc: f64,
    /// The endpoint error of predicting no flow, px.
    #[serde(deserialize_with = "null_as_nan")]
    pub zero_flow_epe: f64,
}

fn scalar(t: &Tensor<1>) -> f64 {
    f64::from(t.clone().into_scalar::<f32>())
}

fn values(t: &Tensor<1>) -> Vec<f32> {
    t.clone().try_into_vec_as::<f32>().expect("f32 tensor")
}

impl Metrics {
    /// Adds a batch: its losses, logits and labels (`paired`, `contact`,
    /// zero-flow errors: host copies, per sample).
    pub fn add(
        &mut self,
        l: &Losses,
        out: &crate::models::Outputs,
        paired: &[f32],
        contact_next: &[f32],
        zero_flow_epe: &[f32],
    ) {
        let n = paired.len() as u64;
        let np = paired.iter().filter(|&&p| p > 0.5).count() as u64;
        self.samples += n;
        self.paired += np;
        let (nf, npf) = (n as f64, np as f64);
        let s = &mut self.sums;
        s.total += scalar(&l.total) * nf;
        let add = |acc: &mut f64, t: &Option<Tensor<1>>, k: f64| {
            if let Some(t) = t {
                *acc += scalar(t) * k;
            } else {
                *acc = f64::NAN;
            }
        };
        add(&mut s.flow, &l.flow, npf);
        add(&mut s.mask, &l.mask, npf);
        add(&mut s.contact, &l.contact, npf);
        add(&mut s.ee, &l.ee, npf);
        add(&mut s.pairing, &l.pairing, nf);
        add(&mut s.kl, &l.kl, nf);
        match &l.recon {
            Some([r, w, p]) => {
                s.recon_rgb += scalar(r) * nf;
                s.recon_wrench += scalar(w) * nf;
                s.recon_proprio += scalar(p) * nf;
            }
            None => {
                s.recon_rgb = f64::NAN;
                s.recon_wrench = f64::NAN;
                s.recon_proprio = f64::NAN;
            }
        }
        for (i, &p) in paired.iter().enumerate() {
            if p > 0.5 {
                self.contact_positive += (contact_next[i] > 0.5) as u64;
                self.zero_flow_sum += zero_flow_epe[i] as f64;
            }
        }
        self.pairing_positive += np;
        if let Some(c) = &out.contact_logits {
            self.contact_batches += 1;
            for ((x, y), p) in values(c).iter().zip(contact_next).zip(paired) {
                if *p > 0.5 && (*x > 0.0) == (*y > 0.5) {
                    self.contact_right += 1;
                }
            }
        }
        if let (Some(c), Some(_)) = (&out.pairing_logits, &l.pairing) {
            self.pairing_batches += 1;
            for (x, y) in values(c).iter().zip(paired) {
                if (*x > 0.0) == (*y > 0.5) {
                    self.pairing_right += 1;
                }
            }
        }
    }

    /// The means, as a table row (NaN where nothing was measured: no
    /// samples, or a head the model lacks).
    pub fn row(&self, epoch: u32, split: &str) -> Row {
        let nan_if = |none: bool, x: f64| if none { f64::NAN } else { x };
        let n = nan_if(self.samples == 0, self.samples as f64);
        let np = nan_if(self.paired == 0, self.paired as f64);
        let s = &self.sums;
        let pos = self.contact_positive as f64 / np;
        let pair_pos = self.pairing_positive as f64 / n;
        Row {
            epoch,
            split: split.into(),
            samples: self.samples,
            loss: Terms {
                total: s.total / n,
                flow: s.flow / np,
                mask: s.mask / np,
                contact: s.contact / np,
                pairing: s.pairing / n,
                ee: s.ee / np,
                kl: s.kl / n,
                recon_rgb: s.recon_rgb / n,
                recon_wrench: s.recon_wrench / n,
                recon_proprio: s.recon_proprio / n,
            },
            contact_acc: nan_if(self.contact_batches == 0, self.contact_right as f64 / np),
            pairing_acc: nan_if(self.pairing_batches == 0, self.pairing_right as f64 / n),
            contact_majority_acc: pos.max(1.0 - pos),
            pairing_majority_acc: pair_pos.max(1.0 - pair_pos),
            zero_flow_epe: self.zero_flow_sum / np,
        }
    }
}

/// The CSV header of [`Row`]s.
pub const CSV_HEADER: &str = "epoch,split,samples,total,flow_epe_px,mask_bce,contact_bce,contact_acc,pairing_bce,pairing_acc,ee_mse,kl,recon_rgb,recon_wrench,recon_proprio,contact_majority_acc,pairing_majority_acc,zero_flow_epe_px";

impl Row {
    /// The values after `epoch` and `split`, in [`CSV_HEADER`]'s order
    /// (the one list the CSV line and the TensorBoard scalars share).
    fn values(&self) -> [f64; 16] {
        let l = &self.loss;
        [
            self.samples as f64,
            l.total,
            l.flow,
            l.mask,
            l.contact,
            self.contact_acc,
            l.pairing,
            self.pairing_acc,
            l.ee,
            l.kl,
            l.recon_rgb,
            l.recon_wrench,
            l.recon_proprio,
            self.contact_majority_acc,
            self.pairing_majority_acc,
            self.zero_flow_epe,
        ]
    }

    /// The CSV line's values after `epoch` and `split`, named by the
    /// header's columns and prefixed with the split (`train/total`, …): the
    /// TensorBoard scalars of the row.
    pub fn scalars(&self) -> Vec<(String, f64)> {
        CSV_HEADER
            .split(',')
            .skip(2)
            .zip(self.values())
            .map(|(name, v)| (format!("{}/{name}", self.split), v))
            .collect()
    }

    /// One CSV line (no newline).
    pub fn csv(&self) -> String {
        use std::fmt::Write;
        // Digits after the point of each column after `samples` (None: the
        // end-effector MSE, in scientific notation with 6).
        const DIGITS: [Option<usize>; 15] = [
            Some(6),
            Some(6),
            Some(6),
            Some(6),
            Some(5),
            Some(6),
            Some(5),
            None,
            Some(4),
            Some(6),
            Some(6),
            Some(6),
            Some(5),
            Some(5),
            Some(6),
        ];
        let mut line = format!("{},{},{}", self.epoch, self.split, self.samples);
        for (x, digits) in self.values()[1..].iter().zip(DIGITS) {
            let _ = match digits {
                Some(d) => write!(line, ",{x:.d$}"),
                None => write!(line, ",{x:.6e}"),
            };
        }
        line
    }
}

/// Writes the learning curves of `rows` into `dir`: one PNG per quantity
/// (train and test against epochs); a quantity the model lacks is skipped.
pub fn write_curves(
    rows: &[Row],
    dir: &Path,
    title: &str,
) -> Result<Vec<String>, crate::plot::PlotError> {
    type Get = fn(&Row) -> f64;
    let quantities: [(&str, &str, Get); 8] = [
        ("total", "weighted total loss", |r| r.loss.total),
        ("flow", "flow endpoint error, px", |r| r.loss.flow),
        ("ee", "end-effector MSE (normalised)", |r| r.loss.ee),
        ("contact_loss", "contact cross-entropy", |r| r.loss.contact),
        ("contact_acc", "contact accuracy", |r| r.contact_acc),
        ("pairing_loss", "pairing cross-entropy", |r| r.loss.pairing),
        ("pairing_acc", "pairing accuracy", |r| r.pairing_acc),
        ("recon_rgb", "RGB reconstruction MSE", |r| r.loss.recon_rgb),
    ];
    let mut written = Vec::new();
    for (name, label, get) in quantities {
        let mut chart = Chart::new(&format!("{title}: {label}"), "epoch", label);
        let mut any = false;
        for split in ["train", "test"] {
            let pts: Vec<(f64, f64)> = rows
                .iter()
                .filter(|r| r.split == split)
                .map(|r| (r.epoch as f64, get(r)))
                .filter(|p| p.1.is_finite())
                .collect();
            if !pts.is_empty() {
                any = true;
                chart = chart.with(Series::line(split, pts));
            }
        }
        if any {
            let file = format!("curve_{name}.png");
            chart.write_png(dir.join(&file))?;
            written.push(file);
        }
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The CSV line keeps its columns' formats, and the scalars name the
    /// same values by the header's columns.
    #[test]
    fn the_csv_line_and_the_scalars_carry_the_same_values() {
        let row = Row {
            epoch: 2,
            split: "test".into(),
            samples: 64,
            loss: Terms {
                total: 1.234_567_89,
                flow: 2.5,
                mask: 0.1,
                contact: 0.2,
                pairing: 0.3,
                ee: 0.000_123_456_78,
                kl: 12.345_67,
                recon_rgb: f64::NAN,
                recon_wrench: 0.4,
                recon_proprio: 0.5,
            },
            contact_acc: 0.912_345_6,
            pairing_acc: 0.7,
            contact_majority_acc: 0.6,
            pairing_majority_acc: 0.5,
            zero_flow_epe: 3.25,
        };
        assert_eq!(
            row.csv(),
            "2,test,64,1.234568,2.500000,0.100000,0.200000,0.91235,0.300000,0.70000,\
             1.234568e-4,12.3457,NaN,0.400000,0.500000,0.60000,0.50000,3.250000"
        );
        let s = row.scalars();
        assert_eq!(s.len(), CSV_HEADER.split(',').count() - 2);
        assert_eq!(s[0], ("test/samples".to_string(), 64.0));
        assert_eq!(s[8], ("test/ee_mse".to_string(), 0.000_123_456_78));
        assert_eq!(s[15], ("test/zero_flow_epe_px".to_string(), 3.25));
    }

    /// A variant without a pairing head (No-Pairing) has NaN accuracies;
    /// serde_json writes them as null, and a mid-epoch checkpoint must
    /// still read back.
    #[test]
    fn rows_and_sums_with_absent_heads_read_back_from_json() {
        let row = Row {
            epoch: 3,
            split: "train".into(),
            samples: 10,
            loss: Terms {
                pairing: f64::NAN,
                kl: f64::NAN,
                ..Terms::default()
            },
            contact_acc: f64::NAN,
            pairing_acc: f64::NAN,
            contact_majority_acc: 0.9,
            pairing_majority_acc: f64::NAN,
            zero_flow_epe: f64::NAN,
        };
        let text = serde_json::to_string(&row).unwrap();
        assert!(text.contains("\"pairing_acc\":null"), "{text}");
        let back: Row = serde_json::from_str(&text).expect("a row with nulls reads back");
        assert!(back.pairing_acc.is_nan() && back.contact_acc.is_nan());
        assert!(back.loss.pairing.is_nan() && back.zero_flow_epe.is_nan());
        assert_eq!(back.contact_majority_acc, 0.9);

        let m = Metrics {
            zero_flow_sum: f64::NAN,
            ..Metrics::default()
        };
        let back: Metrics = serde_json::from_str(&serde_json::to_string(&m).unwrap()).unwrap();
        assert!(back.zero_flow_sum.is_nan());
    }
}
