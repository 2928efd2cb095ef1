//! The top-level records of an MCAP file, walked one by one so that every
//! problem is named by its byte offset: the structural scan, the salvage
//! that recovery writes from, chunk decompression with bounds, and the
//! summary's CRC check. The mcap crate still parses each record.

use mcap::records::{self, Record};
use std::collections::BTreeMap;

const OP_FOOTER: u8 = 0x02;
const OP_DATA_END: u8 = 0x0F;
/// Opcodes a data section may hold at top level: header, schema, channel,
/// message, chunk, message index, attachment, metadata, data end.
const DATA_SECTION_OPS: [u8; 9] = [0x01, 0x03, 0x04, 0x05, 0x06, 0x07, 0x09, 0x0C, 0x0F];
pub(super) const OP_CHUNK: u8 = 0x06;
const OP_MESSAGE: u8 = 0x05;
/// Largest chunk the reader will decompress: a corrupted size field must
/// not make it allocate without bound.
const MAX_CHUNK_BYTES: u64 = 1 << 30;
/// Largest ratio of a chunk's uncompressed size to its stored bytes. Our
/// logs compress 2–30× (camera frames least, the 1 kHz frames most); the
/// bound keeps what a file can make the reader hold proportional to the
/// file, so a 100 kB file cannot ask for gigabytes.
const MAX_CHUNK_RATIO: u64 = 1000;

/// One top-level record, or where the walk stopped.
enum Walk<'a> {
    Record {
        offset: u64,
        op: u8,
        body: &'a [u8],
    },
    /// The footer and the closing magic: the file is complete.
    End,
    Problem {
        offset: u64,
        what: String,
    },
}

/// Walks the top-level records after the opening magic.
struct Walker<'a> {
    buf: &'a [u8],
    pos: usize,
    done: bool,
}

impl<'a> Walker<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Self {
            buf,
            pos: mcap::MAGIC.len(),
            done: false,
        }
    }
}

impl<'a> Iterator for Walker<'a> {
    type Item = Walk<'a>;

    fn next(&mut self) -> Option<Walk<'a>> {
        if self.done {
            return None;
        }
        let (buf, at) = (self.buf, self.pos);
        let problem = |what: String| Walk::Problem {
            offset: at as u64,
            what,
        };
        let left = buf.len() - at;
        let item = if left == 0 {
            problem("the file ends here, with no footer".into())
        } else if left < 9 {
            problem(format!("a record header needs 9 bytes, {left} left"))
        } else {
            let op = buf[at];
            let len = u64::from_le_bytes(buf[at + 1..at + 9].try_into().expect("8 bytes"));
            if len > (left - 9) as u64 {
                problem(format!(
                    "record (opcode 0x{op:02x}) declares {len} bytes, only {} left in the file",
                    left - 9
                ))
            } else {
                let body = &buf[at + 9..at + 9 + len as usize];
                self.pos = at + 9 + len as usize;
                if op == OP_FOOTER {
                    self.done = true;
                    return Some(if &buf[self.pos..] == mcap::MAGIC {
                        Walk::End
                    } else {
                        Walk::Problem {
                            offset: self.pos as u64,
                            what: "the footer is not followed by the closing MCAP magic".into(),
                        }
                    });
                }
                return Some(Walk::Record {
                    offset: at as u64,
                    op,
                    body,
                });
            }
        };
        self.done = true;
        Some(item)
    }
}

/// The records of a chunk (decompressed and CRC-checked), or why not.
///
/// Decompressed here rather than by the mcap crate's chunk reader, whose
/// buffers trust the record lengths inside the chunk: a damaged chunk must
/// be an error, not an allocation of exabytes.
pub(super) fn chunk_records(body: &[u8]) -> Result<Vec<Record<'static>>, String> {
    let (header, data) = match mcap::read::parse_record(OP_CHUNK, body) {
        Ok(Record::Chunk { header, data }) => (header, data),
        Ok(_) => return Err("not a chunk".into()),
        Err(e) => return Err(format!("chunk header: {e}")),
    };
    if header.uncompressed_size > MAX_CHUNK_BYTES {
        return Err(format!(
            "chunk claims {} bytes uncompressed (more than the {MAX_CHUNK_BYTES} allowed)",
            header.uncompressed_size
        ));
    }
    let stored = data.len() as u64;
    if header.uncompressed_size > stored.max(1).saturating_mul(MAX_CHUNK_RATIO) {
        return Err(format!(
            "chunk claims {} bytes uncompressed from {stored} stored (more than \
             {MAX_CHUNK_RATIO} times)",
            header.uncompressed_size
        ));
    }
    // Optional in the MCAP specification (0), written by every writer we
    // read (ours, the Python and C++ libraries): without it a flipped bit
    // in a chunk would read back as different data, unnoticed. (An empty
    // chunk's CRC is 0.)
    if header.uncompressed_crc == 0 && header.uncompressed_size > 0 {
        return Err("chunk has no CRC (0); this reader requires chunk CRCs".into());
    }
    let size = header.uncompressed_size as usize;
    let plain: Vec<u8> = match header.compression.as_str() {
        "" => data.into_owned(),
        "zstd" => {
            let mut out = vec![0u8; size];
            let n = zstd::bulk::decompress_to_buffer(&data, &mut out)
                .map_err(|e| format!("zstd: {e}"))?;
            out.truncate(n);
            out
        }
        other => return Err(format!("unsupported chunk compression {other:?}")),
    };
    if plain.len() != size {
        return Err(format!(
            "chunk holds {} bytes uncompressed, its header says {size}",
            plain.len()
        ));
    }
    if crc32fast::hash(&plain) != header.uncompressed_crc {
        return Err("chunk CRC mismatch".into());
    }
    let mut out = Vec::new();
    let mut at = 0usize;
    while at < plain.len() {
        let left = plain.len() - at;
        if left < 9 {
            return Err(format!(
                "record header at chunk byte {at} needs 9 bytes, {left} left"
            ));
        }
        let op = plain[at];
        let len = u64::from_le_bytes(plain[at + 1..at + 9].try_into().expect("8 bytes"));
        if len > (left - 9) as u64 {
            return Err(format!(
                "record (opcode 0x{op:02x}) at chunk byte {at} declares {len} bytes, {} left",
                left - 9
            ));
        }
        let body = &plain[at + 9..at + 9 + len as usize];
        let r = mcap::read::parse_record(op, body)
            .map_err(|e| format!("record (opcode 0x{op:02x}) at chunk byte {at}: {e}"))?;
        out.push(r.into_owned());
        at += 9 + len as usize;
    }
    Ok(out)
}

/// What a structural scan found.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct ScanReport {
    /// Complete chunks (decompressed and parsed).
    pub chunks: u64,
    /// Messages in them and outside them.
    pub messages: u64,
    /// Bytes of intact records from the start.
    pub readable_bytes: u64,
    /// The footer and closing magic are there.
    pub complete: bool,
    /// The first problem: byte offset and what.
    pub problem: Option<(u64, String)>,
}

/// Schemas, channels and messages found by a linear walk (recovery input).
#[derive(Default)]
pub(super) struct Salvage {
    pub(super) profile: String,
    pub(super) schemas: BTreeMap<u16, (String, String, Vec<u8>)>,
    pub(super) channels: BTreeMap<u16, records::Channel>,
    pub(super) messages: Vec<(records::MessageHeader, Vec<u8>)>,
}

pub(super) fn walk_all(buf: &[u8], mut salvage: Option<&mut Salvage>) -> ScanReport {
    let mut rep = ScanReport::default();
    if !buf.starts_with(mcap::MAGIC) {
        rep.problem = Some((0, "no MCAP magic".into()));
        return rep;
    }
    rep.readable_bytes = mcap::MAGIC.len() as u64;
    let mut keep = |r: Record<'_>, rep: &mut ScanReport| match r {
        Record::Header(h) => {
            if let Some(s) = salvage.as_deref_mut() {
                s.profile = h.profile;
            }
        }
        // The first record of an id is the one its messages were written
        // under; a later one with the same id (damaged) must not replace it.
        Record::Schema { header, data } => {
            if let Some(s) = salvage.as_deref_mut() {
                s.schemas.entry(header.id).or_insert((
                    header.name,
                    header.encoding,
                    data.into_owned(),
                ));
            }
        }
        Record::Channel(c) => {
            if let Some(s) = salvage.as_deref_mut() {
                s.channels.entry(c.id).or_insert(c);
            }
        }
        Record::Message { header, data } => {
            rep.messages += 1;
            if let Some(s) = salvage.as_deref_mut() {
                s.messages.push((header, data.into_owned()));
            }
        }
        _ => {}
    };
    // After the data end comes the summary: copies of the schemas and
    // channels, not covered by any chunk CRC; parsed (a scan reports its
    // damage) but never salvaged.
    let mut in_summary = false;
    for item in Walker::new(buf) {
        match item {
            Walk::End => {
                rep.complete = true;
                rep.readable_bytes = buf.len() as u64;
            }
            Walk::Problem { offset, what } => rep.problem = Some((offset, what)),
            Walk::Record { offset, op, body } => {
                let end = offset + 9 + body.len() as u64;
                if op == OP_CHUNK {
                    match chunk_records(body) {
                        Ok(records) => {
                            rep.chunks += 1;
                            for r in records {
                                keep(r, &mut rep);
                            }
                        }
                        Err(what) => {
                            rep.problem = Some((offset, what));
                            break;
                        }
                    }
                } else {
                    in_summary |= op == OP_DATA_END;
                    // A record the data section cannot hold is damage (a
                    // flipped opcode): skipping it as an unknown record
                    // would skip a whole chunk and salvage past a gap.
                    if !in_summary && !DATA_SECTION_OPS.contains(&op) {
                        rep.problem = Some((
                            offset,
                            format!("record opcode 0x{op:02x} does not belong in the data section"),
                        ));
                        break;
                    }
                    // A chunked file keeps its messages in chunks: a bare
                    // message among them is a flipped opcode (a message
                    // index, whose first field is a real channel id, reads
                    // as a message of that channel) and must not be salvaged.
                    if !in_summary && op == OP_MESSAGE && rep.chunks > 0 {
                        rep.problem = Some((
                            offset,
                            "a message record outside the chunks of a chunked file".into(),
                        ));
                        break;
                    }
                    match mcap::read::parse_record(op, body) {
                        Ok(r) if !in_summary => keep(r, &mut rep),
                        Ok(_) => {}
                        Err(e) => {
                            rep.problem = Some((offset, format!("record 0x{op:02x}: {e}")));
                            break;
                        }
                    }
                }
                rep.readable_bytes = end;
            }
        }
    }
    rep
}

/// Checks the summary section against the footer's CRC (the mcap crate's
/// summary reader does not): the reader takes every channel and chunk
/// location from the summary, so a flipped bit there would otherwise drop
/// or misname messages silently.
pub(super) fn check_summary_crc(buf: &[u8]) -> Result<(), (u64, String)> {
    // Footer record: opcode, length 20, summary start, summary offset
    // start, summary CRC; then the closing magic.
    const FOOTER: usize = 1 + 8 + 20;
    let magic = mcap::MAGIC.len();
    let Some(at) = buf.len().checked_sub(magic + FOOTER) else {
        return Err((0, "too short for a footer".into()));
    };
    let f = &buf[at..at + FOOTER];
    let u64_at = |o: usize| u64::from_le_bytes(f[o..o + 8].try_into().expect("8 bytes"));
    let start = u64_at(9);
    let crc = u32::from_le_bytes(f[25..29].try_into().expect("4 bytes"));
    if f[0] != OP_FOOTER || u64_at(1) != 20 {
        return Err((at as u64, "the footer record is damaged".into()));
    }
    if start == 0 {
        return Ok(()); // no summary: the caller names that
    }
    if crc == 0 {
        return Err((
            at as u64,
            "the summary has no CRC (0); this reader requires one".into(),
        ));
    }
    if start > at as u64 {
        return Err((
            at as u64,
            format!("the footer's summary start {start} lies past it"),
        ));
    }
    // The CRC covers the summary up to the footer's CRC field.
    if crc32fast::hash(&buf[start as usize..at + 25]) != crc {
        return Err((start, "summary CRC mismatch".into()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn walker_names_the_offset_of_a_truncated_record() {
        let mut buf = mcap::MAGIC.to_vec();
        buf.push(0x01); // a header record
        buf.extend_from_slice(&100u64.to_le_bytes());
        buf.extend_from_slice(&[0; 10]);
        let rep = walk_all(&buf, None);
        let (offset, what) = rep.problem.unwrap();
        assert_eq!(offset, 8);
        assert!(what.contains("declares 100 bytes"), "{what}");
        assert_eq!(rep.readable_bytes, 8);
    }
}
