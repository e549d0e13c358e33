//! An MCAP file's messages, with their channels and schemas (and the
//! types a ROS 1 bag's reader gives its messages too).
//!
//! The container (its framing, chunks, their compression and CRCs) is
//! `mcap`'s sans-I/O reader's; the three records a replay needs from it
//! (Schema, Channel, Message) are taken apart here rather than by
//! `mcap::parse_record`, whose string fields reserve the length they
//! declare before reading it (a Channel claiming a 4 GB topic name
//! allocated 4 GB: found by the `ros2_bag` fuzz target). Every length
//! here is checked against the bytes of its record first. Other records
//! (indexes, statistics, attachments, metadata) are passed over.

use std::collections::HashMap;
use std::sync::Arc;

use mcap::records::op;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};

/// The first bytes of an MCAP file.
pub const MCAP_MAGIC: &[u8] = b"\x89MCAP0\r\n";

/// The longest record (a chunk's, uncompressed) the reader takes: a range
/// image's bound (`MAX_IMAGE_BYTES`).
const RECORD_LIMIT: usize = 1 << 28;

/// A message definition as the file gives it.
#[derive(Debug)]
pub struct SchemaInfo {
    pub name: String,
    pub encoding: String,
    pub data: Vec<u8>,
    /// ROS 1's md5sum of the type (a bag's connections give it).
    pub md5sum: Option<String>,
}

/// A channel: its topic, its messages' encoding and their schema.
#[derive(Debug)]
pub struct ChannelInfo {
    pub topic: String,
    pub message_encoding: String,
    pub schema: Option<Arc<SchemaInfo>>,
}

/// One message, copied out of the file.
#[derive(Debug)]
pub struct RawMessage {
    pub channel: Arc<ChannelInfo>,
    /// Nanoseconds.
    pub log_time: u64,
    pub data: Vec<u8>,
}

/// The messages of an MCAP file in file order; an error ends them.
pub struct Records<'a> {
    bytes: &'a [u8],
    fed: usize,
    reader: LinearReader,
    schemas: HashMap<u16, Arc<SchemaInfo>>,
    channels: HashMap<u16, Arc<ChannelInfo>>,
    done: bool,
}

impl<'a> Records<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        let options = LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_record_length_limit(RECORD_LIMIT);
        // Read no further than the first uncompressed chunk whose records
        // overrun it: mcap's reader subtracts such a record's length from
        // what the chunk has left (an overflow: a panic where overflow is
        // checked, garbage where not). Found by the `ros2_bag` fuzz target.
        Self {
            bytes: overrun(bytes).map_or(bytes, |at| &bytes[..at]),
            fed: 0,
            reader: LinearReader::new_with_options(options),
            schemas: HashMap::new(),
            channels: HashMap::new(),
            done: false,
        }
    }

    /// Bytes of the file read so far.
    pub fn position(&self) -> u64 {
        self.fed as u64
    }

    fn record(&mut self, opcode: u8, data: &[u8]) -> Result<Option<RawMessage>, String> {
        let mut r = Fields(data);
        match opcode {
            op::SCHEMA => {
                let id = r.u16()?;
                let schema = SchemaInfo {
                    name: r.string()?,
                    encoding: r.string()?,
                    data: r.bytes()?.to_vec(),
                    md5sum: None,
                };
                if id != 0 && self.schemas.len() < MAX_DEFINITIONS {
                    self.schemas.insert(id, Arc::new(schema));
                }
                Ok(None)
            }
            op::CHANNEL => {
                let id = r.u16()?;
                let schema_id = r.u16()?;
                let channel = ChannelInfo {
                    topic: r.string()?,
                    message_encoding: r.string()?,
                    schema: self.schemas.get(&schema_id).cloned(),
                };
                if self.channels.len() < MAX_DEFINITIONS || self.channels.contains_key(&id) {
                    self.channels.insert(id, Arc::new(channel));
                }
                Ok(None)
            }
            op::MESSAGE => {
                let channel_id = r.u16()?;
                let _sequence = r.u32()?;
                let log_time = r.u64()?;
                let _publish_time = r.u64()?;
                let channel = self.channels.get(&channel_id).cloned().ok_or_else(|| {
                    format!("a message on channel {channel_id}, which no Channel record defines")
                })?;
                Ok(Some(RawMessage {
                    channel,
                    log_time,
                    data: r.0.to_vec(),
                }))
            }
            _ => Ok(None),
        }
    }
}

/// The most schemas, and channels, a file may define (each further one is
/// left out, its messages then on an undefined channel).
const MAX_DEFINITIONS: usize = 65_536;

impl Iterator for Records<'_> {
    type Item = Result<RawMessage, String>;

    fn next(&mut self) -> Option<Self::Item> {
        while !self.done {
            let (opcode, data) = match self.reader.next_event() {
                None => {
                    self.done = true;
                    return None;
                }
                Some(Err(e)) => {
                    self.done = true;
                    return Some(Err(e.to_string()));
                }
                Some(Ok(LinearReadEvent::ReadRequest(wanted))) => {
                    let n = wanted.min(self.bytes.len() - self.fed);
                    self.reader
                        .insert(n)
                        .copy_from_slice(&self.bytes[self.fed..self.fed + n]);
                    self.reader.notify_read(n);
                    self.fed += n;
                    continue;
                }
                Some(Ok(LinearReadEvent::Record { opcode, data })) => (opcode, data.to_vec()),
            };
            match self.record(opcode, &data) {
                Ok(Some(message)) => return Some(Ok(message)),
                Ok(None) => {}
                Err(e) => {
                    self.done = true;
                    return Some(Err(format!("record {opcode:#04x}: {e}")));
                }
            }
        }
        None
    }
}

/// Where the first chunk that does not fit starts (cut short by the
/// file's end, or uncompressed with records overrunning it), if one does
/// not: the file is read up to there (and found cut short). Walks the
/// top-level records' headers only.
fn overrun(bytes: &[u8]) -> Option<usize> {
    const HEAD: usize = 9;
    let mut at = MCAP_MAGIC.len();
    while let Some(head) = bytes.get(at..at + HEAD) {
        let len = u64::from_le_bytes(head[1..].try_into().unwrap_or_default());
        let body = usize::try_from(len)
            .ok()
            .and_then(|len| len.checked_add(at + HEAD))
            .and_then(|end| bytes.get(at + HEAD..end));
        match body {
            // A chunk cut short by the file's end is read no more than one
            // that does not fit.
            _ if head[0] != op::CHUNK => {}
            Some(body) if chunk_fits(body) => {}
            _ => return Some(at),
        }
        at = at + HEAD + body?.len();
    }
    None
}

/// Whether a chunk's header fits in it and, uncompressed, its records
/// each fit in what its header says they take, and that in the chunk (a
/// compressed one's records are mcap's to check as it decompresses).
fn chunk_fits(body: &[u8]) -> bool {
    let mut r = Fields(body);
    if r.take(8 + 8 + 8 + 4).is_err() {
        return false;
    }
    let (Ok(compression), Ok(len)) = (r.bytes(), r.u64()) else {
        return false;
    };
    let Ok(records) = r.take(usize::try_from(len).unwrap_or(usize::MAX)) else {
        return false;
    };
    if !compression.is_empty() {
        return true;
    }
    let mut records = Fields(records);
    while !records.0.is_empty() {
        let fits = records
            .take(1)
            .and_then(|_| records.u64())
            .and_then(|n| records.take(usize::try_from(n).unwrap_or(usize::MAX)));
        if fits.is_err() {
            return false;
        }
    }
    true
}

/// A record's fields, read from its front, every length checked.
pub(super) struct Fields<'a>(pub(super) &'a [u8]);

impl<'a> Fields<'a> {
    pub(super) fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        if n > self.0.len() {
            return Err(format!(
                "a field of {n} bytes where {} are left",
                self.0.len()
            ));
        }
        let (head, rest) = self.0.split_at(n);
        self.0 = rest;
        Ok(head)
    }

    pub(super) fn u16(&mut self) -> Result<u16, String> {
        Ok(u16::from_le_bytes(
            self.take(2)?.try_into().unwrap_or_default(),
        ))
    }

    pub(super) fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().unwrap_or_default(),
        ))
    }

    pub(super) fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().unwrap_or_default(),
        ))
    }

    pub(super) fn bytes(&mut self) -> Result<&'a [u8], String> {
        let n = self.u32()?;
        self.take(usize::try_from(n).unwrap_or(usize::MAX))
    }

    pub(super) fn string(&mut self) -> Result<String, String> {
        let bytes = self.bytes()?;
        String::from_utf8(bytes.to_vec()).map_err(|_| "a string that is not UTF-8".to_owned())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// MCAP's magic, a header, then `records` (opcode, body), a data end, a
    /// footer and the magic again.
    fn file(records: &[(u8, Vec<u8>)]) -> Vec<u8> {
        let mut out = MCAP_MAGIC.to_vec();
        let mut push = |op: u8, body: &[u8]| {
            out.push(op);
            out.extend_from_slice(&(body.len() as u64).to_le_bytes());
            out.extend_from_slice(body);
        };
        push(op::HEADER, &[0u8; 8]);
        for (op, body) in records {
            push(*op, body);
        }
        push(op::DATA_END, &[0u8; 4]);
        push(op::FOOTER, &[0u8; 20]);
        out.extend_from_slice(MCAP_MAGIC);
        out
    }

    pub(super) fn string(s: &str) -> Vec<u8> {
        let mut out = (s.len() as u32).to_le_bytes().to_vec();
        out.extend_from_slice(s.as_bytes());
        out
    }

    fn channel(topic_len_claimed: Option<u32>) -> Vec<u8> {
        let mut body = vec![1, 0, 0, 0];
        match topic_len_claimed {
            Some(n) => {
                body.extend_from_slice(&n.to_le_bytes());
                body.extend_from_slice(b"/points");
            }
            None => body.extend(string("/points")),
        }
        body.extend(string("cdr"));
        body.extend_from_slice(&0u32.to_le_bytes());
        body
    }

    fn message() -> Vec<u8> {
        let mut body = vec![1, 0];
        body.extend_from_slice(&0u32.to_le_bytes());
        body.extend_from_slice(&7u64.to_le_bytes());
        body.extend_from_slice(&7u64.to_le_bytes());
        body.extend_from_slice(b"payload");
        body
    }

    #[test]
    fn messages_come_with_their_channel_and_a_length_past_its_record_is_an_error() {
        let good = file(&[(op::CHANNEL, channel(None)), (op::MESSAGE, message())]);
        let all: Vec<_> = Records::new(&good).collect();
        assert_eq!(all.len(), 1, "{all:?}");
        let m = all[0].as_ref().unwrap();
        assert_eq!((m.channel.topic.as_str(), m.log_time), ("/points", 7));
        assert_eq!(m.data, b"payload");
        // A topic claiming 4 GB: an error, nothing reserved.
        let bad = file(&[
            (op::CHANNEL, channel(Some(u32::MAX))),
            (op::MESSAGE, message()),
        ]);
        let all: Vec<_> = Records::new(&bad).collect();
        assert_eq!(all.len(), 1);
        assert!(
            all[0].as_ref().unwrap_err().contains("4294967295 bytes"),
            "{all:?}"
        );
        // A message on a channel never defined.
        let orphan = file(&[(op::MESSAGE, message())]);
        let all: Vec<_> = Records::new(&orphan).collect();
        assert!(
            all[0].as_ref().unwrap_err().contains("no Channel record"),
            "{all:?}"
        );
        // An uncompressed chunk whose record claims more than the chunk
        // holds (the file going on past it): the file ends before it, an
        // error, never a panic.
        let mut chunk = vec![0u8; 28];
        chunk.extend_from_slice(&0u32.to_le_bytes());
        chunk.extend_from_slice(&13u64.to_le_bytes());
        chunk.push(op::MESSAGE);
        chunk.extend_from_slice(&100u64.to_le_bytes());
        chunk.extend_from_slice(&[0u8; 4]);
        let overrun = file(&[
            (op::CHANNEL, channel(None)),
            (op::MESSAGE, message()),
            (op::CHUNK, chunk),
            (op::METADATA, vec![0u8; 300]),
        ]);
        let all: Vec<_> = Records::new(&overrun).collect();
        assert!(
            all.len() == 2 && all[0].is_ok() && all[1].is_err(),
            "{all:?}"
        );
        // Cut short: an error, after what came before.
        let cut = &good[..good.len() - 30];
        let all: Vec<_> = Records::new(cut).collect();
        assert!(
            all.len() == 2 && all[0].is_ok() && all[1].is_err(),
            "{all:?}"
        );
    }
}
