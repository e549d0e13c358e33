//! A ROS 1 bag's messages (format 2.0), with their connections.
//!
//! A bag is a magic line, then records: each a header (`name=value`
//! fields, `op` among them) and data, both length-prefixed. The bag header
//! (`op` 3) says where the index starts; before it, chunks (`op` 5: `none`,
//! `bz2` or `lz4`) hold connection records (`op` 7: topic, type, md5sum,
//! definition) and message data (`op` 2: connection, time, bytes), and
//! index data (`op` 4) that a reader in file order passes over.
//!
//! Read here in file order, every length checked against the bytes it
//! lies in before anything is taken or allocated: a chunk's declared size
//! is bounded ([`CHUNK_LIMIT`]) and its data decompressed (by `bzip2`,
//! `lz4_flex`) into no more than that. A bag whose recording was cut off
//! (no index yet: `index_pos` 0) is read to its end, and one cut short
//! ends at the last whole record, the damage named. (The `rosbag` crate
//! maps a file itself, slices its chunk section by the header's
//! `index_pos` unchecked, and reserves a chunk's declared size before
//! decompressing it: none of which a bag's bytes may decide here.)

use std::collections::HashMap;
use std::io::Read as _;
use std::sync::Arc;

use super::records::{ChannelInfo, Fields, RawMessage, SchemaInfo};

/// The first bytes of a ROS 1 bag.
pub const ROS1_MAGIC: &[u8] = b"#ROSBAG V2.0\n";

/// The largest chunk, uncompressed, a bag may have (a range image's bound,
/// as for MCAP's records).
const CHUNK_LIMIT: usize = 1 << 28;

/// The most connections a bag may define (each further one is left out,
/// its messages then on an undefined connection).
const MAX_CONNECTIONS: usize = 65_536;

const OP_MESSAGE: u8 = 0x02;
const OP_BAG_HEADER: u8 = 0x03;
const OP_CHUNK: u8 = 0x05;
const OP_CONNECTION: u8 = 0x07;

/// One record: its header's fields and its data.
struct Record<'a> {
    fields: Vec<(&'a str, &'a [u8])>,
    data: &'a [u8],
}

impl<'a> Record<'a> {
    /// The record at the front of `bytes`, and what follows it.
    fn read(bytes: &'a [u8]) -> Result<(Self, &'a [u8]), String> {
        let mut r = Fields(bytes);
        let header = r.bytes().map_err(|e| format!("a record's header: {e}"))?;
        let data = r.bytes().map_err(|e| format!("a record's data: {e}"))?;
        let fields = fields_of(header).map_err(|e| format!("a record's header: {e}"))?;
        Ok((Self { fields, data }, r.0))
    }

    fn field(&self, name: &str) -> Option<&'a [u8]> {
        self.fields
            .iter()
            .find(|(n, _)| *n == name)
            .map(|(_, v)| *v)
    }

    fn op(&self) -> Result<u8, String> {
        match self.field("op") {
            Some(&[op]) => Ok(op),
            _ => Err("a record without a one-byte `op`".into()),
        }
    }

    fn u32(&self, name: &str) -> Result<u32, String> {
        self.field(name)
            .and_then(|v| v.try_into().ok())
            .map(u32::from_le_bytes)
            .ok_or_else(|| format!("a record without a 4-byte `{name}`"))
    }

    fn u64(&self, name: &str) -> Result<u64, String> {
        self.field(name)
            .and_then(|v| v.try_into().ok())
            .map(u64::from_le_bytes)
            .ok_or_else(|| format!("a record without an 8-byte `{name}`"))
    }

    fn text(&self, name: &str) -> Result<String, String> {
        let value = self
            .field(name)
            .ok_or_else(|| format!("a record without `{name}`"))?;
        String::from_utf8(value.to_vec()).map_err(|_| format!("`{name}` that is not UTF-8"))
    }
}

/// The messages of a ROS 1 bag in file order; an error ends them.
pub struct Ros1Records<'a> {
    /// The chunk section still to read (to the index, or the file's end).
    rest: &'a [u8],
    /// Bytes of the file before `rest`.
    offset: usize,
    /// The chunk being read, decompressed, and how far.
    chunk: Vec<u8>,
    at: usize,
    connections: HashMap<u32, Arc<ChannelInfo>>,
    /// Why the bag cannot be read at all, given at the first `next`.
    refused: Option<String>,
    /// Why it ends before its index, given after its last message.
    cut: Option<String>,
    done: bool,
}

impl<'a> Ros1Records<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        let mut records = Self {
            rest: &[],
            offset: 0,
            chunk: Vec::new(),
            at: 0,
            connections: HashMap::new(),
            refused: None,
            cut: None,
            done: false,
        };
        match Self::chunk_section(bytes) {
            Ok((start, end, cut)) => {
                records.rest = &bytes[start..end];
                records.offset = start;
                records.cut = cut;
            }
            Err(e) => records.refused = Some(e),
        }
        records
    }

    /// Where the chunk section starts and ends: after the bag header, to
    /// its `index_pos` (the file's end when it is 0: not yet indexed; or
    /// past the end: cut short, said in the third).
    fn chunk_section(bytes: &[u8]) -> Result<(usize, usize, Option<String>), String> {
        let body = bytes
            .strip_prefix(ROS1_MAGIC)
            .ok_or("it does not start with `#ROSBAG V2.0`")?;
        let (header, rest) = Record::read(body).map_err(|e| format!("the bag header: {e}"))?;
        if header.op()? != OP_BAG_HEADER {
            return Err("the first record is not the bag header".into());
        }
        let start = bytes.len() - rest.len();
        let index = header.u64("index_pos")?;
        match usize::try_from(index) {
            Ok(0) => Ok((start, bytes.len(), None)),
            Ok(end) if (start..=bytes.len()).contains(&end) => Ok((start, end, None)),
            // Past the end: the file was cut short (a copy interrupted);
            // what it holds is read, and the loss named after it.
            _ if index >= start as u64 => Ok((
                start,
                bytes.len(),
                Some(format!(
                    "the bag header puts the index at byte {index}, past the file's {} bytes: \
                     the bag is cut short",
                    bytes.len()
                )),
            )),
            _ => Err(format!(
                "the bag header puts the index at byte {index}, inside the header itself"
            )),
        }
    }

    /// Bytes of the file read so far.
    pub fn position(&self) -> u64 {
        self.offset as u64
    }

    /// The next record of the chunk section, decompressing a chunk into
    /// `self.chunk`; `None` at its end.
    fn next_outer(&mut self) -> Result<Option<()>, String> {
        while !self.rest.is_empty() {
            let (record, rest) = Record::read(self.rest)
                .map_err(|e| format!("at byte {}: {e} (the bag is cut short?)", self.offset))?;
            let at = self.offset;
            self.offset += self.rest.len() - rest.len();
            self.rest = rest;
            match record.op()? {
                OP_CHUNK => {
                    self.chunk =
                        decompress(&record).map_err(|e| format!("the chunk at byte {at}: {e}"))?;
                    self.at = 0;
                    return Ok(Some(()));
                }
                OP_CONNECTION => connection(&mut self.connections, &record)?,
                // Index data, chunk info: what a reader in order passes over.
                _ => {}
            }
        }
        Ok(None)
    }

    /// The next message of the chunk being read, if any is left in it.
    fn next_inner(&mut self) -> Result<Option<RawMessage>, String> {
        let in_chunk = |e| format!("in a chunk: {e}");
        while self.at < self.chunk.len() {
            let (record, rest) = Record::read(&self.chunk[self.at..]).map_err(in_chunk)?;
            self.at = self.chunk.len() - rest.len();
            match record.op().map_err(in_chunk)? {
                OP_MESSAGE => {
                    let id = record.u32("conn").map_err(in_chunk)?;
                    let time = record.u64("time").map_err(in_chunk)?;
                    // Seconds, then nanoseconds, each 32 bits.
                    let ns = (time & 0xffff_ffff) * 1_000_000_000 + (time >> 32);
                    let channel = self.connections.get(&id).cloned().ok_or_else(|| {
                        in_chunk(format!(
                            "a message on connection {id}, which no record defines"
                        ))
                    })?;
                    return Ok(Some(RawMessage {
                        channel,
                        log_time: ns,
                        data: record.data.to_vec(),
                    }));
                }
                OP_CONNECTION => connection(&mut self.connections, &record).map_err(in_chunk)?,
                _ => {}
            }
        }
        Ok(None)
    }
}

/// Defines (or defines again) a connection from its record: its topic,
/// and from its description the type, md5sum and definition.
fn connection(
    connections: &mut HashMap<u32, Arc<ChannelInfo>>,
    record: &Record<'_>,
) -> Result<(), String> {
    let id = record.u32("conn")?;
    let topic = record.text("topic")?;
    let description = Record {
        fields: fields_of(record.data).map_err(|e| format!("connection {id}: {e}"))?,
        data: &[],
    };
    let text = |name: &str| {
        description
            .field(name)
            .map(|v| String::from_utf8_lossy(v).into_owned())
    };
    let channel = ChannelInfo {
        topic,
        message_encoding: "ros1".into(),
        schema: Some(Arc::new(SchemaInfo {
            name: text("type").unwrap_or_default(),
            encoding: "ros1msg".into(),
            data: text("message_definition").unwrap_or_default().into_bytes(),
            md5sum: text("md5sum"),
        })),
    };
    if connections.len() < MAX_CONNECTIONS || connections.contains_key(&id) {
        connections.insert(id, Arc::new(channel));
    }
    Ok(())
}

/// `name=value` fields, each length-prefixed: a record's header, or a
/// connection's description (its data).
fn fields_of(bytes: &[u8]) -> Result<Vec<(&str, &[u8])>, String> {
    let mut fields = Vec::new();
    let mut h = Fields(bytes);
    while !h.0.is_empty() {
        let field = h.bytes()?;
        let at = field
            .iter()
            .position(|&b| b == b'=')
            .ok_or("a field without `=`")?;
        let name =
            std::str::from_utf8(&field[..at]).map_err(|_| "a field name that is not UTF-8")?;
        fields.push((name, &field[at + 1..]));
    }
    Ok(fields)
}

/// A chunk's records, decompressed: no more than its declared `size`
/// (itself at most [`CHUNK_LIMIT`]), and exactly that.
fn decompress(chunk: &Record<'_>) -> Result<Vec<u8>, String> {
    let size = chunk.u32("size")? as usize;
    if size > CHUNK_LIMIT {
        return Err(format!(
            "{size} bytes uncompressed, past the {CHUNK_LIMIT} a chunk may hold"
        ));
    }
    let compression = chunk.text("compression")?;
    let data = chunk.data;
    let mut out = Vec::new();
    let read = |reader: &mut dyn std::io::Read, out: &mut Vec<u8>| {
        reader
            .take(size as u64 + 1)
            .read_to_end(out)
            .map_err(|e| format!("{compression} data that does not decompress: {e}"))
    };
    match compression.as_str() {
        "none" => out.extend_from_slice(data),
        "bz2" => {
            read(&mut bzip2::read::BzDecoder::new(data), &mut out)?;
        }
        "lz4" => {
            read(&mut lz4_flex::frame::FrameDecoder::new(data), &mut out)?;
        }
        other => return Err(format!("compression {other:?} (not none, bz2 or lz4)")),
    }
    if out.len() != size {
        let found = if out.len() > size {
            format!("more than {size}")
        } else {
            out.len().to_string()
        };
        return Err(format!(
            "{found} bytes of records, where its header says {size}"
        ));
    }
    Ok(out)
}

impl Iterator for Ros1Records<'_> {
    type Item = Result<RawMessage, String>;

    fn next(&mut self) -> Option<Self::Item> {
        if let Some(why) = self.refused.take() {
            self.done = true;
            return Some(Err(why));
        }
        while !self.done {
            match self.next_inner() {
                Ok(Some(message)) => return Some(Ok(message)),
                Ok(None) => {}
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            }
            match self.next_outer() {
                Ok(Some(())) => {}
                Ok(None) => {
                    self.done = true;
                    return self.cut.take().map(Err);
                }
                Err(e) => {
                    self.done = true;
                    return Some(Err(e));
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn field(name: &str, value: &[u8]) -> Vec<u8> {
        let mut f = ((name.len() + 1 + value.len()) as u32)
            .to_le_bytes()
            .to_vec();
        f.extend_from_slice(name.as_bytes());
        f.push(b'=');
        f.extend_from_slice(value);
        f
    }

    fn record(fields: &[(&str, &[u8])], data: &[u8]) -> Vec<u8> {
        let header: Vec<u8> = fields.iter().flat_map(|(n, v)| field(n, v)).collect();
        let mut r = (header.len() as u32).to_le_bytes().to_vec();
        r.extend_from_slice(&header);
        r.extend_from_slice(&(data.len() as u32).to_le_bytes());
        r.extend_from_slice(data);
        r
    }

    /// A bag of one plain chunk: a connection on /odom and `messages`
    /// messages on it; `index_pos` as given (`None`: the file's end).
    fn bag(messages: usize, index_pos: Option<u64>, size_claimed: Option<u32>) -> Vec<u8> {
        let description: Vec<u8> = [
            ("topic", &b"/odom"[..]),
            ("type", b"nav_msgs/Odometry"),
            ("md5sum", b"cd5e73d190d741a2f92e81eda573aca7"),
        ]
        .iter()
        .flat_map(|(n, v)| field(n, v))
        .collect();
        let mut inner = record(
            &[
                ("op", &[OP_CONNECTION]),
                ("conn", &7u32.to_le_bytes()),
                ("topic", b"/odom"),
            ],
            &description,
        );
        for k in 0..messages {
            // Seconds k, then 500 ns.
            let time = (k as u64) | (500u64 << 32);
            inner.extend(record(
                &[
                    ("op", &[OP_MESSAGE]),
                    ("conn", &7u32.to_le_bytes()),
                    ("time", &time.to_le_bytes()),
                ],
                &[k as u8; 3],
            ));
        }
        let size = size_claimed.unwrap_or(inner.len() as u32);
        let chunk = record(
            &[
                ("op", &[OP_CHUNK]),
                ("compression", b"none"),
                ("size", &size.to_le_bytes()),
            ],
            &inner,
        );
        let header_len = record(
            &[("op", &[OP_BAG_HEADER]), ("index_pos", &0u64.to_le_bytes())],
            &[],
        )
        .len();
        let end = (ROS1_MAGIC.len() + header_len + chunk.len()) as u64;
        let mut out = ROS1_MAGIC.to_vec();
        out.extend(record(
            &[
                ("op", &[OP_BAG_HEADER]),
                ("index_pos", &index_pos.unwrap_or(end).to_le_bytes()),
            ],
            &[],
        ));
        out.extend(chunk);
        out
    }

    #[test]
    fn messages_come_with_their_connection_and_time_and_damage_ends_them_named() {
        let whole = bag(3, None, None);
        let all: Vec<_> = Ros1Records::new(&whole).collect::<Result<_, _>>().unwrap();
        assert_eq!(all.len(), 3);
        assert_eq!(all[2].channel.topic, "/odom");
        assert_eq!(all[2].log_time, 2 * 1_000_000_000 + 500);
        assert_eq!(all[2].data, [2u8; 3]);
        let schema = all[0].channel.schema.as_ref().unwrap();
        assert_eq!(schema.name, "nav_msgs/Odometry");
        assert_eq!(
            schema.md5sum.as_deref(),
            Some("cd5e73d190d741a2f92e81eda573aca7")
        );
        // Not yet indexed (a recording cut off): read to the file's end.
        let unindexed = bag(3, Some(0), None);
        assert_eq!(
            Ros1Records::new(&unindexed).filter(Result::is_ok).count(),
            3
        );
        // Cut short inside the chunk: nothing of it, and the damage named.
        let cut = &whole[..whole.len() - 5];
        let all: Vec<_> = Ros1Records::new(cut).collect();
        assert_eq!(all.len(), 1);
        assert!(
            all[0].as_ref().unwrap_err().contains("cut short"),
            "{all:?}"
        );
        // An index past the file's end: what is there, then the loss named.
        let past = bag(3, Some(1 << 40), None);
        let all: Vec<_> = Ros1Records::new(&past).collect();
        assert_eq!(all.len(), 4);
        assert!(
            all[3].as_ref().unwrap_err().contains("cut short"),
            "{all:?}"
        );
        assert!(
            all[3]
                .as_ref()
                .unwrap_err()
                .contains("puts the index at byte 1099511627776")
        );
        // A chunk claiming 4 GB uncompressed: refused, nothing allocated.
        let huge = bag(3, None, Some(u32::MAX));
        let all: Vec<_> = Ros1Records::new(&huge).collect();
        assert!(all[0].as_ref().unwrap_err().contains("past the"), "{all:?}");
        // One claiming less than it holds.
        let short = bag(3, None, Some(10));
        let all: Vec<_> = Ros1Records::new(&short).collect();
        assert!(
            all[0]
                .as_ref()
                .unwrap_err()
                .contains("where its header says 10"),
            "{all:?}"
        );
        // Not a bag at all.
        let all: Vec<_> = Ros1Records::new(b"#ROSBAG V1.2\n").collect();
        assert!(all[0].is_err());
    }
}
