//! MCAP files built byte by byte, each with one thing a hostile or broken
//! writer could do that our writer never does: a chunk indexed twice, a
//! chunk that asks for far more memory than the file holds, no CRCs. Each
//! is refused with an error naming the problem (and the offset), before
//! anything is allocated from the claim.

use learner_node::log::{LogReader, ReadError};
use std::path::Path;

fn rec(op: u8, body: &[u8]) -> Vec<u8> {
    let mut out = vec![op];
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(body);
    out
}

fn string(s: &str) -> Vec<u8> {
    let mut out = (s.len() as u32).to_le_bytes().to_vec();
    out.extend_from_slice(s.as_bytes());
    out
}

/// What to get wrong in [`build`].
#[derive(Default, Clone, Copy)]
struct Fault {
    /// Index the chunk twice in the summary.
    index_twice: bool,
    /// The chunk's uncompressed size claimed (instead of the true one).
    claim_size: Option<u64>,
    /// Write 0 (no CRC) for the chunk.
    no_chunk_crc: bool,
    /// Write 0 (no CRC) for the summary.
    no_summary_crc: bool,
}

/// One channel `/a` (schema `t`, JSON) and one uncompressed chunk of three
/// messages, with a summary of the schema, the channel and the chunk index.
fn build(f: Fault) -> Vec<u8> {
    let schema = {
        let mut b = 1u16.to_le_bytes().to_vec();
        b.extend(string("t"));
        b.extend(string("jsonschema"));
        b.extend(string("{}"));
        rec(0x03, &b)
    };
    let channel = {
        let mut b = 1u16.to_le_bytes().to_vec();
        b.extend(1u16.to_le_bytes());
        b.extend(string("/a"));
        b.extend(string("json"));
        b.extend(0u32.to_le_bytes()); // no metadata
        rec(0x04, &b)
    };
    let mut records = schema.clone();
    records.extend(&channel);
    for i in 0..3u64 {
        let mut b = 1u16.to_le_bytes().to_vec();
        b.extend((i as u32).to_le_bytes());
        b.extend((10 + i).to_le_bytes());
        b.extend((10 + i).to_le_bytes());
        b.extend(format!("{{\"i\":{i}}}").as_bytes());
        records.extend(rec(0x05, &b));
    }
    let crc = if f.no_chunk_crc {
        0
    } else {
        crc32fast::hash(&records)
    };
    let size = f.claim_size.unwrap_or(records.len() as u64);
    let chunk = {
        let mut b = 10u64.to_le_bytes().to_vec();
        b.extend(12u64.to_le_bytes());
        b.extend(size.to_le_bytes());
        b.extend(crc.to_le_bytes());
        b.extend(string(""));
        b.extend((records.len() as u64).to_le_bytes());
        b.extend(&records);
        rec(0x06, &b)
    };
    let mut out = mcap::MAGIC.to_vec();
    let mut header = string("");
    header.extend(string("hand-built"));
    out.extend(rec(0x01, &header));
    let chunk_at = out.len() as u64;
    out.extend(&chunk);
    out.extend(rec(0x0F, &0u32.to_le_bytes()));
    let summary_at = out.len() as u64;
    out.extend(&schema);
    out.extend(&channel);
    let index = {
        let mut b = 10u64.to_le_bytes().to_vec();
        b.extend(12u64.to_le_bytes());
        b.extend(chunk_at.to_le_bytes());
        b.extend((chunk.len() as u64).to_le_bytes());
        b.extend(0u32.to_le_bytes()); // no message indexes
        b.extend(0u64.to_le_bytes());
        b.extend(string(""));
        b.extend((records.len() as u64).to_le_bytes());
        b.extend(size.to_le_bytes());
        rec(0x08, &b)
    };
    for _ in 0..if f.index_twice { 2 } else { 1 } {
        out.extend(&index);
    }
    let footer_at = out.len();
    let mut footer = summary_at.to_le_bytes().to_vec();
    footer.extend(0u64.to_le_bytes());
    footer.extend(0u32.to_le_bytes());
    out.extend(rec(0x02, &footer));
    if !f.no_summary_crc {
        let crc = crc32fast::hash(&out[summary_at as usize..footer_at + 25]);
        out[footer_at + 25..footer_at + 29].copy_from_slice(&crc.to_le_bytes());
    }
    out.extend(mcap::MAGIC);
    out
}

fn open(f: Fault) -> Result<LogReader, ReadError> {
    LogReader::from_bytes(Path::new("hand.mcap"), build(f))
}

#[test]
fn the_hand_built_file_reads_back_its_three_messages() {
    let msgs = open(Fault::default()).unwrap().read(&[], None).unwrap();
    let data: Vec<&[u8]> = msgs.iter().map(|m| &m.data[..]).collect();
    assert_eq!(data, [&b"{\"i\":0}"[..], b"{\"i\":1}", b"{\"i\":2}"]);
}

#[test]
fn a_chunk_indexed_twice_is_refused_not_read_twice() {
    let e = open(Fault {
        index_twice: true,
        ..Fault::default()
    })
    .err()
    .expect("refused");
    let text = e.to_string();
    assert!(matches!(e, ReadError::Corrupt { .. }), "{text}");
    assert!(text.contains("two chunk indexes"), "{text}");
    assert!(text.contains("hand.mcap"), "{text}");
}

#[test]
fn a_chunk_cannot_claim_more_than_a_thousand_times_its_bytes() {
    // A few hundred bytes that ask for 1 GiB and for 1 000× + 1.
    let stored = build(Fault::default()).len() as u64; // more than the records
    for claim in [1u64 << 30, 1 << 29, 1000 * stored + 1] {
        let r = open(Fault {
            claim_size: Some(claim),
            ..Fault::default()
        })
        .unwrap();
        let e = r.read(&[], None).expect_err("refused");
        let text = e.to_string();
        assert!(text.contains(&format!("claims {claim} bytes")), "{text}");
        assert!(text.contains("offset"), "{text}");
    }
}

#[test]
fn chunks_and_summaries_without_a_crc_are_refused() {
    let r = open(Fault {
        no_chunk_crc: true,
        ..Fault::default()
    })
    .unwrap();
    let e = r.read(&[], None).expect_err("refused").to_string();
    assert!(e.contains("chunk has no CRC"), "{e}");
    let e = open(Fault {
        no_summary_crc: true,
        ..Fault::default()
    })
    .err()
    .expect("refused")
    .to_string();
    assert!(e.contains("summary has no CRC"), "{e}");
}
