//! LCM's UDP multicast protocol.
//!
//! A message whose `channel NUL data` fits in 65 499 bytes travels as one
//! `LC02` datagram: `u32 magic, u32 seqno, channel, NUL, data`. A larger one is
//! split into `LC03` fragments: `u32 magic, u32 seqno, u32 msg_size,
//! u32 fragment_offset, u16 fragment_no, u16 fragments_in_msg, payload`,
//! fragment 0 carrying `channel NUL` before its data. All big-endian.
//!
//! The [`Reassembler`] keeps received fragments per sender, holding only what
//! actually arrived (a forged `msg_size` allocates nothing), bounds the memory
//! of all sets in progress, and expires incomplete sets instead of
//! accumulating them.

use std::collections::{BTreeMap, HashMap};
use std::net::SocketAddr;
use std::time::{Duration, Instant};

/// `LC02`: a message in one datagram.
pub const MAGIC_SHORT: u32 = 0x4c43_3032;
/// `LC03`: one fragment of a message.
pub const MAGIC_LONG: u32 = 0x4c43_3033;
const SHORT_HEADER_LEN: usize = 8;
const LONG_HEADER_LEN: usize = 20;
/// Largest `channel NUL data` sent as one `LC02` datagram.
pub const MAX_SHORT_PAYLOAD: usize = 65_499;
/// Payload bytes of an `LC03` fragment (fragment 0 includes `channel NUL`).
pub const FRAGMENT_PAYLOAD: usize = 65_487;
/// Longest channel name LCM accepts.
pub const MAX_CHANNEL_LEN: usize = 63;
/// Largest message LCM accepts (2^28 bytes).
pub const MAX_MESSAGE_SIZE: usize = 1 << 28;
/// Incomplete fragment sets older than this are dropped.
pub const FRAGMENT_EXPIRY: Duration = Duration::from_secs(1);
/// Memory all fragment sets in progress may hold together.
pub const MAX_REASSEMBLY_BYTES: usize = 64 << 20;

/// Calls `send` with each datagram of one message, in order.
pub fn for_each_datagram<E>(
    seqno: u32,
    channel: &str,
    data: &[u8],
    mut send: impl FnMut(&[u8]) -> Result<(), E>,
) -> Result<(), E> {
    let mut packet = Vec::with_capacity(LONG_HEADER_LEN + FRAGMENT_PAYLOAD);
    if channel.len() + 1 + data.len() <= MAX_SHORT_PAYLOAD {
        packet.extend_from_slice(&MAGIC_SHORT.to_be_bytes());
        packet.extend_from_slice(&seqno.to_be_bytes());
        packet.extend_from_slice(channel.as_bytes());
        packet.push(0);
        packet.extend_from_slice(data);
        return send(&packet);
    }
    let first = data.len().min(FRAGMENT_PAYLOAD - (channel.len() + 1));
    let rest = data.len() - first;
    let fragments = 1 + rest.div_ceil(FRAGMENT_PAYLOAD);
    // Callers refuse messages over MAX_MESSAGE_SIZE, so both fit.
    let fragments = fragments as u16;
    let msg_size = data.len() as u32;
    let mut offset = 0usize;
    for fragment_no in 0..fragments {
        let len = if fragment_no == 0 {
            first
        } else {
            (data.len() - offset).min(FRAGMENT_PAYLOAD)
        };
        packet.clear();
        packet.extend_from_slice(&MAGIC_LONG.to_be_bytes());
        packet.extend_from_slice(&seqno.to_be_bytes());
        packet.extend_from_slice(&msg_size.to_be_bytes());
        packet.extend_from_slice(&(offset as u32).to_be_bytes());
        packet.extend_from_slice(&fragment_no.to_be_bytes());
        packet.extend_from_slice(&fragments.to_be_bytes());
        if fragment_no == 0 {
            packet.extend_from_slice(channel.as_bytes());
            packet.push(0);
        }
        packet.extend_from_slice(&data[offset..offset + len]);
        send(&packet)?;
        offset += len;
    }
    Ok(())
}

/// What the reassembler has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ReassemblyStats {
    pub datagrams: u64,
    pub messages: u64,
    /// Datagrams that were not LCM or were inconsistent.
    pub malformed: u64,
    /// Fragment sets dropped before completion (expired, replaced by a newer
    /// message from the same sender, or evicted to bound memory).
    pub incomplete: u64,
}

struct FragmentSet {
    seqno: u32,
    msg_size: usize,
    fragments: u16,
    channel: Option<String>,
    parts: BTreeMap<u16, (usize, Vec<u8>)>,
    bytes: usize,
    started: Instant,
}

/// Turns datagrams back into messages.
#[derive(Default)]
pub struct Reassembler {
    sets: HashMap<SocketAddr, FragmentSet>,
    bytes: usize,
    stats: ReassemblyStats,
}

impl Reassembler {
    pub fn stats(&self) -> ReassemblyStats {
        self.stats
    }

    /// Fragment sets in progress.
    pub fn pending(&self) -> usize {
        self.sets.len()
    }

    /// Feeds one datagram; returns a message when one is complete.
    pub fn on_datagram(
        &mut self,
        from: SocketAddr,
        datagram: &[u8],
        now: Instant,
    ) -> Option<(String, Vec<u8>)> {
        self.stats.datagrams += 1;
        self.expire(now);
        let message = match datagram
            .get(..4)
            .map(|m| u32::from_be_bytes([m[0], m[1], m[2], m[3]]))
        {
            Some(MAGIC_SHORT) => short_message(datagram),
            Some(MAGIC_LONG) => match self.fragment(from, datagram, now) {
                Ok(message) => return message,
                Err(Malformed) => None,
            },
            _ => None,
        };
        match message {
            Some(m) => {
                self.stats.messages += 1;
                Some(m)
            }
            None => {
                self.stats.malformed += 1;
                None
            }
        }
    }

    /// Drops fragment sets older than [`FRAGMENT_EXPIRY`].
    pub fn expire(&mut self, now: Instant) {
        let before = self.sets.len();
        let mut freed = 0;
        self.sets.retain(|_, set| {
            let keep = now.saturating_duration_since(set.started) < FRAGMENT_EXPIRY;
            if !keep {
                freed += set.bytes;
            }
            keep
        });
        self.bytes -= freed;
        self.stats.incomplete += (before - self.sets.len()) as u64;
    }

    fn drop_set(&mut self, from: &SocketAddr) {
        if let Some(set) = self.sets.remove(from) {
            self.bytes -= set.bytes;
            self.stats.incomplete += 1;
        }
    }

    fn fragment(
        &mut self,
        from: SocketAddr,
        datagram: &[u8],
        now: Instant,
    ) -> Result<Option<(String, Vec<u8>)>, Malformed> {
        let header = datagram.get(..LONG_HEADER_LEN).ok_or(Malformed)?;
        let be32 = |at: usize| {
            u32::from_be_bytes([header[at], header[at + 1], header[at + 2], header[at + 3]])
        };
        let seqno = be32(4);
        let msg_size = be32(8) as usize;
        let offset = be32(12) as usize;
        let fragment_no = u16::from_be_bytes([header[16], header[17]]);
        let fragments = u16::from_be_bytes([header[18], header[19]]);
        if msg_size > MAX_MESSAGE_SIZE || fragments == 0 || fragment_no >= fragments {
            return Err(Malformed);
        }
        let mut payload = &datagram[LONG_HEADER_LEN..];
        let mut channel = None;
        if fragment_no == 0 {
            let (name, rest) = split_channel(payload).ok_or(Malformed)?;
            channel = Some(name);
            payload = rest;
        }
        if offset
            .checked_add(payload.len())
            .is_none_or(|end| end > msg_size)
        {
            return Err(Malformed);
        }
        // A different message from this sender replaces an unfinished one.
        if self
            .sets
            .get(&from)
            .is_some_and(|s| s.seqno != seqno || s.msg_size != msg_size || s.fragments != fragments)
        {
            self.drop_set(&from);
        }
        // Bound memory: evict the oldest sets until this payload fits.
        while self.bytes + payload.len() > MAX_REASSEMBLY_BYTES {
            let Some(oldest) = self
                .sets
                .iter()
                .min_by_key(|(_, s)| s.started)
                .map(|(a, _)| *a)
            else {
                break;
            };
            self.drop_set(&oldest);
        }
        let set = self.sets.entry(from).or_insert_with(|| FragmentSet {
            seqno,
            msg_size,
            fragments,
            channel: None,
            parts: BTreeMap::new(),
            bytes: 0,
            started: now,
        });
        if set.parts.contains_key(&fragment_no) {
            return Ok(None);
        }
        if channel.is_some() {
            set.channel = channel;
        }
        set.parts.insert(fragment_no, (offset, payload.to_vec()));
        set.bytes += payload.len();
        self.bytes += payload.len();
        if set.parts.len() < usize::from(set.fragments) {
            return Ok(None);
        }
        let set = self.sets.remove(&from).ok_or(Malformed)?;
        self.bytes -= set.bytes;
        let channel = set.channel.ok_or(Malformed)?;
        // Every fragment came: they must add up to the size the header
        // claims before that size is allocated.
        if set.bytes != set.msg_size {
            self.stats.malformed += 1;
            return Ok(None);
        }
        let mut data = Vec::with_capacity(set.msg_size);
        for (_, (offset, part)) in set.parts {
            if offset != data.len() {
                self.stats.malformed += 1;
                return Ok(None);
            }
            data.extend_from_slice(&part);
        }
        if data.len() != set.msg_size {
            self.stats.malformed += 1;
            return Ok(None);
        }
        self.stats.messages += 1;
        Ok(Some((channel, data)))
    }
}

struct Malformed;

fn split_channel(payload: &[u8]) -> Option<(String, &[u8])> {
    let nul = payload
        .iter()
        .take(MAX_CHANNEL_LEN + 1)
        .position(|&b| b == 0)?;
    if nul == 0 {
        return None;
    }
    let channel = std::str::from_utf8(&payload[..nul]).ok()?.to_owned();
    Some((channel, &payload[nul + 1..]))
}

fn short_message(datagram: &[u8]) -> Option<(String, Vec<u8>)> {
    let payload = datagram.get(SHORT_HEADER_LEN..)?;
    let (channel, data) = split_channel(payload)?;
    Some((channel, data.to_vec()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn datagrams(seqno: u32, channel: &str, data: &[u8]) -> Vec<Vec<u8>> {
        let mut out = Vec::new();
        for_each_datagram::<()>(seqno, channel, data, |d| {
            out.push(d.to_vec());
            Ok(())
        })
        .unwrap();
        out
    }

    fn sender(port: u16) -> SocketAddr {
        SocketAddr::from(([127, 0, 0, 1], port))
    }

    #[test]
    fn a_small_message_is_one_lc02_datagram() {
        let d = datagrams(7, "POSE", b"abc");
        assert_eq!(d.len(), 1);
        assert_eq!(
            d[0],
            [b"LC02".as_slice(), &[0, 0, 0, 7], b"POSE\0abc"].concat()
        );
        let mut r = Reassembler::default();
        assert_eq!(
            r.on_datagram(sender(1), &d[0], Instant::now()),
            Some(("POSE".into(), b"abc".to_vec()))
        );
    }

    #[test]
    fn the_lc02_limit_is_65499_bytes_of_channel_nul_and_data() {
        let channel = "RANGE_IMAGE";
        let fits = vec![1u8; MAX_SHORT_PAYLOAD - channel.len() - 1];
        assert_eq!(datagrams(0, channel, &fits).len(), 1);
        let over = vec![1u8; fits.len() + 1];
        assert_eq!(datagrams(0, channel, &over).len(), 2);
    }

    #[test]
    fn a_range_image_is_fragmented_like_the_reference_and_reassembled() {
        let channel = "RANGE_IMAGE";
        let data: Vec<u8> = (0..1_050_000u32).map(|i| (i % 251) as u8).collect();
        let d = datagrams(3, channel, &data);
        let first = FRAGMENT_PAYLOAD - (channel.len() + 1);
        assert_eq!(d.len(), 1 + (data.len() - first).div_ceil(FRAGMENT_PAYLOAD));
        assert_eq!(&d[0][..4], b"LC03");
        assert_eq!(d[0].len(), LONG_HEADER_LEN + FRAGMENT_PAYLOAD);
        assert_eq!(
            &d[1][12..16],
            &(first as u32).to_be_bytes(),
            "fragment 1 starts where 0 ended"
        );
        // Delivered out of order, with a duplicate.
        let mut r = Reassembler::default();
        let now = Instant::now();
        let mut order: Vec<usize> = (0..d.len()).rev().collect();
        order.insert(1, d.len() - 1);
        let mut got = None;
        for i in order {
            if let Some(m) = r.on_datagram(sender(1), &d[i], now) {
                got = Some(m);
            }
        }
        assert_eq!(got, Some((channel.to_owned(), data)));
        assert_eq!(r.pending(), 0);
    }

    #[test]
    fn incomplete_fragment_sets_expire_instead_of_accumulating() {
        let data = vec![5u8; 200_000];
        let d = datagrams(1, "BIG", &data);
        let mut r = Reassembler::default();
        let t0 = Instant::now();
        for packet in &d[..d.len() - 1] {
            assert!(r.on_datagram(sender(1), packet, t0).is_none());
        }
        assert_eq!(r.pending(), 1);
        r.expire(t0 + FRAGMENT_EXPIRY);
        assert_eq!(r.pending(), 0);
        assert_eq!(r.stats().incomplete, 1);
        // The last fragment alone, arriving late, completes nothing.
        assert!(
            r.on_datagram(sender(1), &d[d.len() - 1], t0 + FRAGMENT_EXPIRY)
                .is_none()
        );
    }

    #[test]
    fn a_new_message_from_the_same_sender_replaces_an_unfinished_one() {
        let mut r = Reassembler::default();
        let now = Instant::now();
        let a = datagrams(1, "A", &[1u8; 100_000]);
        let b = datagrams(2, "B", &[2u8; 100_000]);
        r.on_datagram(sender(1), &a[0], now);
        let mut out = None;
        for packet in &b {
            out = r.on_datagram(sender(1), packet, now).or(out);
        }
        assert_eq!(out.map(|(c, _)| c), Some("B".to_owned()));
        assert_eq!(r.stats().incomplete, 1);
        // Two senders interleaving is fine.
        let mut r = Reassembler::default();
        let (mut ca, mut cb) = (None, None);
        for (pa, pb) in a.iter().zip(&b) {
            ca = r.on_datagram(sender(1), pa, now).or(ca);
            cb = r.on_datagram(sender(2), pb, now).or(cb);
        }
        assert!(ca.is_some() && cb.is_some());
    }

    #[test]
    fn malformed_datagrams_are_counted_and_never_panic() {
        let mut r = Reassembler::default();
        let now = Instant::now();
        let bad: Vec<Vec<u8>> = vec![
            vec![],
            b"LC0".to_vec(),
            b"XXXXabcd".to_vec(),
            b"LC02\0\0\0\x01no-nul".to_vec(),
            b"LC02\0\0\0\x01\0empty-channel".to_vec(),
            // LC03 declaring 2^30 bytes.
            [
                b"LC03".as_slice(),
                &[0, 0, 0, 1],
                &(1u32 << 30).to_be_bytes(),
                &[0; 4],
                &[0, 0, 0, 2],
                b"C\0x",
            ]
            .concat(),
            // fragment_no >= fragments_in_msg.
            [
                b"LC03".as_slice(),
                &[0, 0, 0, 1],
                &10u32.to_be_bytes(),
                &[0; 4],
                &[0, 2, 0, 2],
                b"x",
            ]
            .concat(),
            // payload running past msg_size.
            [
                b"LC03".as_slice(),
                &[0, 0, 0, 1],
                &2u32.to_be_bytes(),
                &[0; 4],
                &[0, 0, 0, 2],
                b"C\0xyz",
            ]
            .concat(),
        ];
        for d in &bad {
            assert!(r.on_datagram(sender(1), d, now).is_none());
        }
        assert_eq!(r.stats().malformed, bad.len() as u64);
        assert_eq!(r.pending(), 0);
    }

    #[test]
    fn a_forged_size_allocates_only_what_arrived() {
        let mut r = Reassembler::default();
        let header = [
            b"LC03".as_slice(),
            &[0, 0, 0, 9],
            &((1u32 << 28) - 1).to_be_bytes(),
            &[0; 4],
            &[0, 0, 0x10, 0],
        ]
        .concat();
        let d = [header, b"C\0".to_vec(), vec![0u8; 100]].concat();
        assert!(r.on_datagram(sender(1), &d, Instant::now()).is_none());
        assert_eq!(r.bytes, 100);
    }
}
