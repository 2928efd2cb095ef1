//! Configuration files with command-line overrides: `--set key=value`
//! changes one field of a TOML configuration by its dotted path before the
//! file is read into its type, so every setting can be changed from the
//! command line by one mechanism instead of a flag per field.
//!
//! The value is read as a TOML value (`seed=2`, `policy.algorithm="ppo"`,
//! `env.world.task.box_xy_range_m=[0.02, 0.02]`); a value that is not one is
//! taken as a string (`policy.algorithm=ppo`). The type's own
//! deserialisation then checks it, so a misspelt key is refused wherever the
//! type denies unknown fields, and a wrong type is named with its path.

use serde::de::DeserializeOwned;
use std::path::Path;

/// Why a configuration with overrides could not be read.
#[derive(Debug, thiserror::Error)]
pub enum SettingsError {
    /// The file could not be read.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: std::path::PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// An override is not `key=value`, or its key runs through a value
    /// that is not a table.
    #[error("--set {given}: {why}")]
    Override {
        /// The override as given.
        given: String,
        /// What is wrong with it.
        why: String,
    },
    /// The file, with its overrides, is not a valid configuration.
    #[error("{path}{with}: {detail}")]
    Parse {
        /// The file (or "defaults").
        path: String,
        /// " with --set …" when overrides were given.
        with: String,
        /// The parser's message, naming the field.
        detail: String,
    },
}

/// Applies `key=value` overrides to a TOML table, creating the tables a
/// dotted key runs through.
pub fn apply_overrides(doc: &mut toml::Table, sets: &[String]) -> Result<(), SettingsError> {
    for given in sets {
        let bad = |why: &str| SettingsError::Override {
            given: given.clone(),
            why: why.to_string(),
        };
        let (key, raw) = given
            .split_once('=')
            .ok_or_else(|| bad("expected key=value"))?;
        let key = key.trim();
        let path: Vec<&str> = key.split('.').map(str::trim).collect();
        if key.is_empty() || path.iter().any(|p| p.is_empty()) {
            return Err(bad("the key is empty or has an empty part"));
        }
        let value = parse_value(raw.trim());
        let (last, tables) = path.split_last().expect("at least one part");
        let mut table = &mut *doc;
        for (i, part) in tables.iter().enumerate() {
            let entry = table
                .entry(part.to_string())
                .or_insert_with(|| toml::Value::Table(toml::Table::new()));
            table = entry.as_table_mut().ok_or_else(|| {
                bad(&format!(
                    "`{}` is a value, not a table",
                    path[..=i].join(".")
                ))
            })?;
        }
        table.insert(last.to_string(), value);
    }
    Ok(())
}

/// A TOML value, or the text as a string when it is not one.
fn parse_value(raw: &str) -> toml::Value {
    let doc = format!("v = {raw}");
    match doc.parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").expect("parsed key"),
        Err(_) => toml::Value::String(raw.to_string()),
    }
}

/// Reads `path` (or the type's defaults when None) with `sets` applied.
pub fn read_with_overrides<T: DeserializeOwned>(
    path: Option<&Path>,
    sets: &[String],
) -> Result<T, SettingsError> {
    let mut doc = match path {
        Some(p) => {
            let text = std::fs::read_to_string(p).map_err(|source| SettingsError::Io {
                path: p.to_path_buf(),
                source,
            })?;
            text.parse::<toml::Table>()
                .map_err(|e| SettingsError::Parse {
                    path: p.display().to_string(),
                    with: String::new(),
                    detail: e.to_string(),
                })?
        }
        None => toml::Table::new(),
    };
    apply_overrides(&mut doc, sets)?;
    toml::Value::Table(doc)
        .try_into()
        .map_err(|e| SettingsError::Parse {
            path: path.map_or("defaults".into(), |p| p.display().to_string()),
            with: if sets.is_empty() {
                String::new()
            } else {
                format!(" with --set {}", sets.join(" --set "))
            },
            detail: e.to_string(),
        })
}

/// `value` with `sets` applied: a configuration already read (a
/// checkpoint's) changed as a file would be.
pub fn with_overrides<T: serde::Serialize + DeserializeOwned>(
    value: &T,
    sets: &[String],
) -> Result<T, SettingsError> {
    let parse = |detail: String| SettingsError::Parse {
        path: "the configuration".into(),
        with: format!(" with --set {}", sets.join(" --set ")),
        detail,
    };
    let mut doc = toml::Table::try_from(value).map_err(|e| parse(e.to_string()))?;
    apply_overrides(&mut doc, sets)?;
    toml::Value::Table(doc)
        .try_into()
        .map_err(|e: toml::de::Error| parse(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, serde::Deserialize, serde::Serialize, PartialEq, Default)]
    #[serde(default, deny_unknown_fields)]
    struct Inner {
        x: f64,
        name: String,
        list: Vec<u32>,
    }

    #[derive(Debug, serde::Deserialize, serde::Serialize, PartialEq, Default)]
    #[serde(default, deny_unknown_fields)]
    struct Outer {
        seed: u64,
        inner: Inner,
    }

    fn read(sets: &[&str]) -> Result<Outer, SettingsError> {
        let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
        read_with_overrides(None, &sets)
    }

    #[test]
    fn overrides_set_nested_fields_of_every_type() {
        let o = read(&[
            "seed=7",
            "inner.x = 0.5",
            "inner.name=ppo",
            "inner.list=[1, 2]",
        ])
        .unwrap();
        assert_eq!(
            o,
            Outer {
                seed: 7,
                inner: Inner {
                    x: 0.5,
                    name: "ppo".into(),
                    list: vec![1, 2]
                }
            }
        );
        // A quoted string is the same string.
        assert_eq!(read(&["inner.name=\"ppo\""]).unwrap().inner.name, "ppo");
    }

    #[test]
    fn bad_overrides_are_named() {
        let e = read(&["seed"]).unwrap_err().to_string();
        assert!(e.contains("--set seed") && e.contains("key=value"), "{e}");
        let e = read(&["inner.y=1"]).unwrap_err().to_string();
        assert!(e.contains("unknown field `y`"), "{e}");
        let e = read(&["seed=two"]).unwrap_err().to_string();
        assert!(e.contains("--set seed=two"), "{e}");
        let e = read(&["seed=1", "seed.x=2"]).unwrap_err().to_string();
        assert!(e.contains("`seed` is a value"), "{e}");
        let e = read(&[".x=1"]).unwrap_err().to_string();
        assert!(e.contains("empty"), "{e}");
    }

    #[test]
    fn overrides_change_a_value_already_read() {
        let o = Outer {
            seed: 1,
            inner: Inner {
                x: 1.0,
                name: "a".into(),
                list: vec![3],
            },
        };
        let changed = with_overrides(&o, &["inner.x=4".into()]).unwrap();
        assert_eq!(changed.inner.x, 4.0);
        assert_eq!((changed.seed, changed.inner.list), (1, vec![3]));
        assert_eq!(with_overrides(&o, &[]).unwrap(), o);
        assert!(with_overrides(&o, &["inner.z=1".into()]).is_err());
    }

    #[test]
    fn overrides_apply_over_the_file() {
        let dir = std::env::temp_dir().join(format!("settings-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("c.toml");
        std::fs::write(&p, "seed = 3\n[inner]\nx = 1.0\nname = \"a\"\n").unwrap();
        let o: Outer = read_with_overrides(Some(&p), &["inner.x=2".into()]).unwrap();
        assert_eq!((o.seed, o.inner.x, o.inner.name.as_str()), (3, 2.0, "a"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
