//! TensorBoard scalar event files, written without TensorBoard: TFRecord
//! framing (length, masked CRC-32C of the length, the record, masked CRC-32C
//! of the record) around hand-encoded `Event` protocol buffers (`wall_time`
//! = 1, `step` = 2, `file_version` = 3, `summary` = 5; `Summary.value` = 1;
//! `Value.tag` = 1, `Value.simple_value` = 2), as TensorBoard's own event
//! writer lays them out. Files only grow: TensorBoard follows an event file
//! by appending, so a process writes a file of its own
//! (`events.out.tfevents.<unix s>.<host>.<pid>.<n>`) and a resumed run adds a
//! second one beside the first.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// CRC-32C (Castagnoli), the checksum of TFRecord framing.
fn crc32c(data: &[u8]) -> u32 {
    const TABLE: [u32; 256] = {
        let mut t = [0u32; 256];
        let mut i = 0;
        while i < 256 {
            let mut c = i as u32;
            let mut k = 0;
            while k < 8 {
                c = if c & 1 != 0 {
                    0x82F6_3B78 ^ (c >> 1)
                } else {
                    c >> 1
                };
                k += 1;
            }
            t[i] = c;
            i += 1;
        }
        t
    };
    let mut c = !0u32;
    for &b in data {
        c = TABLE[((c ^ u32::from(b)) & 0xff) as usize] ^ (c >> 8);
    }
    !c
}

/// TFRecord's masked CRC.
fn masked_crc(data: &[u8]) -> u32 {
    let c = crc32c(data);
    (c.rotate_right(15)).wrapping_add(0xa282_ead8)
}

fn varint(mut v: u64, out: &mut Vec<u8>) {
    while v >= 0x80 {
        out.push((v as u8) | 0x80);
        v >>= 7;
    }
    out.push(v as u8);
}

fn bytes_field(field: u32, bytes: &[u8], out: &mut Vec<u8>) {
    varint(u64::from(field << 3 | 2), out);
    varint(bytes.len() as u64, out);
    out.extend_from_slice(bytes);
}

/// One `Event` with a scalar summary (or, without one, the file version).
fn event(wall_time: f64, step: i64, body: EventBody<'_>) -> Vec<u8> {
    let mut e = Vec::with_capacity(64);
    e.push(1 << 3 | 1); // wall_time, 64-bit
    e.extend_from_slice(&wall_time.to_le_bytes());
    e.push(2 << 3); // step, varint
    varint(step as u64, &mut e);
    match body {
        EventBody::FileVersion(v) => bytes_field(3, v.as_bytes(), &mut e),
        EventBody::Scalars(values) => {
            let mut summary = Vec::new();
            for (tag, v) in values {
                let mut value = Vec::new();
                bytes_field(1, tag.as_bytes(), &mut value);
                value.push(2 << 3 | 5); // simple_value, 32-bit
                value.extend_from_slice(&v.to_le_bytes());
                bytes_field(1, &value, &mut summary);
            }
            bytes_field(5, &summary, &mut e);
        }
    }
    e
}

enum EventBody<'a> {
    FileVersion(&'a str),
    Scalars(&'a [(&'a str, f32)]),
}

/// Frames one record as TFRecord does.
fn record(data: &[u8], out: &mut impl Write) -> std::io::Result<()> {
    let len = (data.len() as u64).to_le_bytes();
    out.write_all(&len)?;
    out.write_all(&masked_crc(&len).to_le_bytes())?;
    out.write_all(data)?;
    out.write_all(&masked_crc(data).to_le_bytes())
}

fn unix_now_s() -> f64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0.0, |d| d.as_secs_f64())
}

/// An event file of scalars in a run directory.
pub struct ScalarLog {
    out: BufWriter<File>,
    path: PathBuf,
}

impl ScalarLog {
    /// Starts this process's event file in `dir`.
    pub fn create(dir: &Path) -> std::io::Result<Self> {
        static OPENED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = OPENED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let now = unix_now_s();
        let path = dir.join(format!(
            "events.out.tfevents.{}.{}.{}.{n}",
            now as u64,
            super::provenance::host_name(),
            std::process::id()
        ));
        // Never over another file: each start adds one.
        let file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(&path)?;
        let mut out = BufWriter::new(file);
        record(
            &event(now, 0, EventBody::FileVersion("brain.Event:2")),
            &mut out,
        )?;
        out.flush()?;
        Ok(Self { out, path })
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Scalars `values` (tag, value) at `step`, written through at once so
    /// that TensorBoard sees them while the run goes on. Non-finite values
    /// are written as they are (TensorBoard shows NaN).
    pub fn scalars<S: AsRef<str>>(
        &mut self,
        step: u64,
        values: &[(S, f64)],
    ) -> std::io::Result<()> {
        let v: Vec<(&str, f32)> = values
            .iter()
            .map(|(t, x)| (t.as_ref(), *x as f32))
            .collect();
        record(
            &event(unix_now_s(), step as i64, EventBody::Scalars(&v)),
            &mut self.out,
        )?;
        self.out.flush()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn crc32c_matches_the_published_check_value() {
        // RFC 3720's check value of CRC-32C over "123456789".
        assert_eq!(crc32c(b"123456789"), 0xE306_9283);
    }

    #[test]
    fn records_are_framed_with_their_lengths_and_checksums() {
        let mut buf = Vec::new();
        record(b"abc", &mut buf).unwrap();
        assert_eq!(buf.len(), 8 + 4 + 3 + 4);
        assert_eq!(&buf[..8], &3u64.to_le_bytes());
        assert_eq!(&buf[8..12], &masked_crc(&buf[..8]).to_le_bytes());
        assert_eq!(&buf[15..], &masked_crc(b"abc").to_le_bytes());
    }
}
