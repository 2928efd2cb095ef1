//! Configuration plumbing every node shares: one error for a value that
//! cannot be used ([`FieldError`], which names the field), the checks that
//! produce it, and reading a TOML file ([`read_toml`], [`ConfigFileError`]).
//! Every node's configuration validates in this one style, so every bad
//! value reads the same: "`dotted.field` = value: what it must satisfy".

use serde::de::DeserializeOwned;
use std::fmt::Display;
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// A configuration value that cannot be used, with the field that holds it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("`{field}` = {value}: {reason}")]
pub struct FieldError {
    /// Dotted path of the field, e.g. `task.clearance_m` or `impedance.kp[2]`.
    pub field: String,
    /// The offending value, as text.
    pub value: String,
    /// What the field must satisfy.
    pub reason: String,
}

impl FieldError {
    /// The error for `field` holding `value`, which must satisfy `reason`.
    pub fn new(field: impl Into<String>, value: impl Display, reason: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            value: value.to_string(),
            reason: reason.into(),
        }
    }
}

/// Fails with `reason` unless `ok`; the base of every other check.
pub fn ensure(
    ok: bool,
    field: &str,
    value: impl Display,
    reason: impl Into<String>,
) -> Result<(), FieldError> {
    if ok {
        Ok(())
    } else {
        Err(FieldError::new(field, value, reason))
    }
}

/// `value` must be finite and satisfy `ok` (NaN fails every comparison, so
/// `ok` alone would let infinities through).
pub fn check(field: &str, value: f64, ok: bool, reason: &str) -> Result<(), FieldError> {
    ensure(value.is_finite() && ok, field, value, reason)
}

/// `value` must be finite.
pub fn finite(field: &str, value: f64) -> Result<(), FieldError> {
    check(field, value, true, "must be finite")
}

/// `value` must be finite and > 0.
pub fn positive(field: &str, value: f64) -> Result<(), FieldError> {
    check(field, value, value > 0.0, "must be finite and > 0")
}

/// `value` must be finite and >= 0.
pub fn non_negative(field: &str, value: f64) -> Result<(), FieldError> {
    check(field, value, value >= 0.0, "must be finite and >= 0")
}

/// Every entry of `values` must be finite.
pub fn all_finite(field: &str, values: &[f64]) -> Result<(), FieldError> {
    ensure(
        values.iter().all(|v| v.is_finite()),
        field,
        format_args!("{values:?}"),
        "must be finite",
    )
}

/// `value` (a count, an index, a ratio) must lie in `range`.
pub fn within<T: PartialOrd + Display>(
    field: &str,
    value: T,
    range: RangeInclusive<T>,
) -> Result<(), FieldError> {
    let reason = format!("must be in {}..={}", range.start(), range.end());
    ensure(range.contains(&value), field, value, reason)
}

/// A count must be at least `min`.
pub fn at_least<T: PartialOrd + Display>(field: &str, value: T, min: T) -> Result<(), FieldError> {
    let reason = format!("must be at least {min}");
    ensure(value >= min, field, value, reason)
}

/// An interval `[lo, hi]` (a range of magnitudes or of times) must be finite
/// with `0 <= lo <= hi`.
pub fn ordered_pair(field: &str, [lo, hi]: [f64; 2]) -> Result<(), FieldError> {
    ensure(
        lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo <= hi,
        field,
        format_args!("[{lo}, {hi}]"),
        "must be finite with 0 <= first <= second",
    )
}

/// A per-joint list must hold exactly `n_joints` values.
pub fn joint_count(field: &str, len: usize, n_joints: usize) -> Result<(), FieldError> {
    ensure(
        len == n_joints,
        field,
        format_args!("{len} values"),
        format!("must hold {n_joints} values, one per joint"),
    )
}

/// A per-joint setting that broadcasts: no value (keep the default), one
/// (every joint) or one per joint, each finite and >= 0.
pub fn per_joint(field: &str, values: &[f64], n_joints: usize) -> Result<(), FieldError> {
    ensure(
        values.len() <= 1 || values.len() == n_joints,
        field,
        format_args!("{} values", values.len()),
        format!("must hold 0, 1 or {n_joints} values"),
    )?;
    for (i, &v) in values.iter().enumerate() {
        non_negative(&format!("{field}[{i}]"), v)?;
    }
    Ok(())
}

/// A configuration file that could not be read or parsed.
#[derive(Debug, thiserror::Error)]
pub enum ConfigFileError {
    /// The file could not be read.
    #[error("cannot read the configuration {}: {reason}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error (in the message, not a `source`: chained error
        /// printers would say it twice).
        reason: std::io::Error,
    },
    /// The TOML is malformed, has an unknown field or a wrong type.
    #[error("configuration {}: {message}", path.display())]
    Parse {
        /// The file, or a label such as `(text)` for text from memory.
        path: PathBuf,
        /// The parser's message (names the field and the line).
        message: String,
    },
}

/// Parses TOML text into a configuration; `origin` names the text in errors.
pub fn parse_toml<T: DeserializeOwned>(text: &str, origin: &Path) -> Result<T, ConfigFileError> {
    toml::from_str(text).map_err(|e| ConfigFileError::Parse {
        path: origin.to_path_buf(),
        message: e.to_string(),
    })
}

/// Reads and parses a TOML configuration file (values are not validated:
/// that is the configuration's own `validate`).
pub fn read_toml<T: DeserializeOwned>(path: &Path) -> Result<T, ConfigFileError> {
    let text = std::fs::read_to_string(path).map_err(|reason| ConfigFileError::Read {
        path: path.to_path_buf(),
        reason,
    })?;
    parse_toml(&text, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_name_the_field_and_the_value() {
        let e = positive("a.b", f64::NAN).unwrap_err();
        assert_eq!(e.to_string(), "`a.b` = NaN: must be finite and > 0");
        assert!(non_negative("x", f64::INFINITY).is_err());
        assert!(non_negative("x", 0.0).is_ok());
        assert_eq!(
            within("p", 120, 1..=99).unwrap_err().reason,
            "must be in 1..=99"
        );
        assert!(ordered_pair("r", [2.0, 1.0]).is_err());
        assert!(ordered_pair("r", [1.0, 1.0]).is_ok());
        assert!(per_joint("d", &[1.0], 7).is_ok());
        assert!(per_joint("d", &[1.0, 2.0], 7).is_err());
        assert_eq!(per_joint("d", &[1.0, -1.0], 2).unwrap_err().field, "d[1]");
        assert!(joint_count("q", 6, 7).is_err());
        assert!(all_finite("v", &[1.0, f64::NAN]).is_err());
    }

    #[test]
    fn file_errors_name_the_file() {
        let e = read_toml::<toml::Table>(Path::new("/nonexistent/x.toml")).unwrap_err();
        assert!(e.to_string().contains("/nonexistent/x.toml"), "{e}");
        let e = parse_toml::<toml::Table>("a = ", Path::new("(text)")).unwrap_err();
        assert!(e.to_string().contains("(text)"), "{e}");
    }
}
