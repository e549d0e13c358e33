//! Authenticated messages on an open multicast bus.
//!
//! LCM over UDP multicast authenticates nothing: any process on the segment
//! can publish a steering command. With a group key shared by the processes
//! of one vehicle, each message carries a tag that only key holders can
//! compute, and receivers refuse what they cannot verify.
//!
//! ## Wire form
//!
//! The LCM message is sent unchanged (fingerprint and fields) and followed
//! by a 48-byte trailer:
//!
//! | bytes | field |
//! |---|---|
//! | 4 | magic `ARA1` |
//! | 4 | reserved, zero |
//! | 8 | counter: the publisher's clock, µs since the Unix epoch, big-endian, strictly increasing per publisher |
//! | 32 | tag: HMAC-SHA256(key, `arcnav-auth-v1` ‖ u32 BE channel length ‖ channel ‖ message ‖ counter) |
//!
//! The decoders `lcm-gen` writes read the fields they know and ignore what
//! follows, so `lcm-spy`, `lcm-logger` and C or Python subscribers see the
//! message as before; a controller in another language verifies it with
//! any HMAC-SHA256 (`examples/verify_command.py` does it in 40 lines of
//! Python). The channel is in the tag: a command cannot be replayed as a
//! vote.
//!
//! ## What a receiver refuses ([`Refusal`])
//!
//! No trailer; a wrong tag; a counter older than `max_age` or further ahead
//! of the receiver's clock than `max_skew` (the clocks of one vehicle's
//! computers must agree to within it); a counter already accepted on the
//! channel, or older than the newest accepted there by more than the
//! reorder `window`. Every refusal is counted per channel and reason
//! ([`AuthStats`]).
//!
//! Keys come from a file ([`GroupKey::from_file`]), never from the
//! configuration: at least 32 bytes, hex-encoded, readable by its owner only.

use std::collections::{BTreeMap, VecDeque};
use std::path::{Path, PathBuf};

use hmac::{Hmac, Mac};

use crate::channels::ChannelFilter;
use sha2::Sha256;

type HmacSha256 = Hmac<Sha256>;

/// Bytes after the message.
pub const TRAILER_LEN: usize = 48;
const MAGIC: &[u8; 4] = b"ARA1";
const DOMAIN: &[u8] = b"arcnav-auth-v1";
/// The shortest key accepted, bytes.
pub const MIN_KEY_BYTES: usize = 32;
/// Key files are read up to this size.
const MAX_KEY_FILE_BYTES: u64 = 4096;

/// Why a key cannot be used. Each names the file.
#[derive(Debug, thiserror::Error)]
pub enum KeyError {
    #[error("key file {}: cannot read it: {source}", path.display())]
    Unreadable {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("key file {}: is readable by {who} (mode {mode:o}); make it readable by its owner only: chmod 600 {}", path.display(), path.display())]
    Exposed {
        path: PathBuf,
        who: &'static str,
        mode: u32,
    },
    #[error("key file {}: {reason}", path.display())]
    Malformed { path: PathBuf, reason: String },
}

/// The group key of one vehicle's processes.
#[derive(Clone)]
pub struct GroupKey(Vec<u8>);

impl std::fmt::Debug for GroupKey {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GroupKey({} bytes)", self.0.len())
    }
}

impl GroupKey {
    /// A key from raw bytes (at least [`MIN_KEY_BYTES`]).
    pub fn new(bytes: &[u8]) -> Option<Self> {
        (bytes.len() >= MIN_KEY_BYTES).then(|| Self(bytes.to_vec()))
    }

    /// Reads a key file: hex digits (whitespace ignored) for at least
    /// [`MIN_KEY_BYTES`] bytes, readable by its owner only. Generate one
    /// with `head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \n' > key`.
    pub fn from_file(path: &Path) -> Result<Self, KeyError> {
        let unreadable = |source| KeyError::Unreadable {
            path: path.to_owned(),
            source,
        };
        let malformed = |reason: String| KeyError::Malformed {
            path: path.to_owned(),
            reason,
        };
        let metadata = std::fs::metadata(path).map_err(unreadable)?;
        if !metadata.is_file() {
            return Err(malformed("is not a regular file".into()));
        }
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = metadata.permissions().mode() & 0o777;
            if mode & 0o077 != 0 {
                let who = if mode & 0o007 != 0 {
                    "everyone"
                } else {
                    "its group"
                };
                return Err(KeyError::Exposed {
                    path: path.to_owned(),
                    who,
                    mode,
                });
            }
        }
        if metadata.len() > MAX_KEY_FILE_BYTES {
            return Err(malformed(format!(
                "is {} bytes; a key file holds hex digits, at most {MAX_KEY_FILE_BYTES} bytes",
                metadata.len()
            )));
        }
        let text = std::fs::read(path).map_err(unreadable)?;
        Self::parse(&text).map_err(malformed)
    }

    /// A key from a key file's text: hex digits (whitespace between them
    /// ignored), at least [`MIN_KEY_BYTES`] bytes, not one byte repeated.
    /// The error says what is wrong with it.
    pub fn parse(text: &[u8]) -> Result<Self, String> {
        let digits: Vec<u8> = text
            .iter()
            .copied()
            .filter(|b| !b.is_ascii_whitespace())
            .collect();
        if let Some(bad) = digits.iter().find(|b| !b.is_ascii_hexdigit()) {
            return Err(format!(
                "holds '{}', not a hex digit (the key is written in hex)",
                char::from(*bad).escape_default()
            ));
        }
        if !digits.len().is_multiple_of(2) {
            return Err(format!(
                "holds an odd number of hex digits ({})",
                digits.len()
            ));
        }
        let bytes: Vec<u8> = digits
            .chunks(2)
            .map(|pair| (hex_value(pair[0]) << 4) | hex_value(pair[1]))
            .collect();
        if bytes.len() > 1 && bytes.iter().all(|&b| b == bytes[0]) {
            return Err(format!(
                "holds one byte ({:#04x}) repeated: not a secret; make a key with \
                 `head -c 32 /dev/urandom | od -An -tx1 | tr -d ' \\n' > KEYFILE`",
                bytes[0]
            ));
        }
        Self::new(&bytes).ok_or_else(|| {
            format!(
                "holds a {}-byte key; at least {MIN_KEY_BYTES} bytes ({} hex digits) are needed",
                bytes.len(),
                2 * MIN_KEY_BYTES
            )
        })
    }

    fn mac(&self, channel: &str, message: &[u8], counter: u64) -> HmacSha256 {
        // HMAC accepts keys of any length: this cannot fail.
        let mut mac = HmacSha256::new_from_slice(&self.0).expect("HMAC takes any key length");
        mac.update(DOMAIN);
        mac.update(&(channel.len() as u32).to_be_bytes());
        mac.update(channel.as_bytes());
        mac.update(message);
        mac.update(&counter.to_be_bytes());
        mac
    }
}

fn hex_value(digit: u8) -> u8 {
    match digit {
        b'0'..=b'9' => digit - b'0',
        b'a'..=b'f' => digit - b'a' + 10,
        _ => digit - b'A' + 10,
    }
}

/// Appends trailers to outgoing messages.
#[derive(Debug, Clone)]
pub struct Signer {
    key: GroupKey,
    last: u64,
}

impl Signer {
    pub fn new(key: GroupKey) -> Self {
        Self { key, last: 0 }
    }

    /// Appends the trailer of `message` (already in `out`, from
    /// `message_start` on) for `channel`, at clock `now_us` (µs since the
    /// Unix epoch). The counter is `now_us`, or one more than the last one
    /// when the clock has not moved on.
    pub fn sign_in_place(
        &mut self,
        channel: &str,
        out: &mut Vec<u8>,
        message_start: usize,
        now_us: u64,
    ) {
        let counter = now_us.max(self.last + 1);
        self.last = counter;
        let tag = self
            .key
            .mac(channel, &out[message_start..], counter)
            .finalize()
            .into_bytes();
        out.reserve(TRAILER_LEN);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&[0; 4]);
        out.extend_from_slice(&counter.to_be_bytes());
        out.extend_from_slice(&tag);
    }

    /// `message` with its trailer.
    pub fn sign(&mut self, channel: &str, message: &[u8], now_us: u64) -> Vec<u8> {
        let mut out = Vec::with_capacity(message.len() + TRAILER_LEN);
        out.extend_from_slice(message);
        self.sign_in_place(channel, &mut out, 0, now_us);
        out
    }
}

/// Why a message was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Refusal {
    /// No trailer: sent by someone without the key (or with authentication off).
    Unauthenticated,
    /// The tag does not match: forged, tampered with, or another key.
    BadTag,
    /// Older than `max_age` by the receiver's clock.
    Expired,
    /// Further ahead of the receiver's clock than `max_skew`.
    FromFuture,
    /// Its counter was accepted before, or lies further behind the
    /// channel's newest than the reorder window.
    Replayed,
}

impl Refusal {
    pub const ALL: [Refusal; 5] = [
        Refusal::Unauthenticated,
        Refusal::BadTag,
        Refusal::Expired,
        Refusal::FromFuture,
        Refusal::Replayed,
    ];

    /// Its place in [`Refusal::ALL`] (and in [`ChannelCounts::refused`]).
    pub fn index(self) -> usize {
        Refusal::ALL.iter().position(|&r| r == self).unwrap_or(0)
    }

    pub fn name(self) -> &'static str {
        match self {
            Refusal::Unauthenticated => "unauthenticated",
            Refusal::BadTag => "bad tag",
            Refusal::Expired => "expired",
            Refusal::FromFuture => "from the future",
            Refusal::Replayed => "replayed",
        }
    }
}

impl std::fmt::Display for Refusal {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// How fresh a message must be.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Freshness {
    /// Oldest accepted, by the receiver's clock, µs.
    pub max_age_us: u64,
    /// Furthest ahead of the receiver's clock accepted, µs.
    pub max_skew_us: u64,
    /// Furthest behind the channel's newest accepted counter, µs.
    pub window_us: u64,
}

impl Default for Freshness {
    fn default() -> Self {
        Self {
            max_age_us: 1_000_000,
            max_skew_us: 250_000,
            window_us: 200_000,
        }
    }
}

/// Accepted and refused messages of one channel.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ChannelCounts {
    pub accepted: u64,
    /// Per [`Refusal::ALL`].
    pub refused: [u64; 5],
}

impl ChannelCounts {
    pub fn refused_total(&self) -> u64 {
        self.refused.iter().sum()
    }
}

/// Counts per channel.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AuthStats {
    pub channels: BTreeMap<String, ChannelCounts>,
}

impl AuthStats {
    pub fn accepted_total(&self) -> u64 {
        self.channels.values().map(|c| c.accepted).sum()
    }

    pub fn refused_total(&self) -> u64 {
        self.channels
            .values()
            .map(ChannelCounts::refused_total)
            .sum()
    }

    /// One line per channel with refusals, e.g.
    /// `STEERING_COMMAND: 12 refused (bad tag 10, replayed 2), 400 accepted`.
    pub fn refusal_lines(&self) -> Vec<String> {
        self.channels
            .iter()
            .filter(|(_, c)| c.refused_total() > 0)
            .map(|(channel, c)| {
                let reasons: Vec<String> = Refusal::ALL
                    .iter()
                    .zip(c.refused)
                    .filter(|(_, n)| *n > 0)
                    .map(|(r, n)| format!("{r} {n}"))
                    .collect();
                format!(
                    "{channel}: {} refused ({}), {} accepted",
                    c.refused_total(),
                    reasons.join(", "),
                    c.accepted
                )
            })
            .collect()
    }
}

/// Counters accepted on one channel within the reorder window.
#[derive(Debug, Clone, Default)]
struct Window {
    /// Ascending.
    accepted: VecDeque<u64>,
}

/// Accepted counters kept per channel: at 1 kHz, 200 ms of them. Beyond,
/// the oldest are forgotten and anything older than the oldest kept is
/// refused, so the window only ever narrows.
const MAX_KEPT: usize = 256;

impl Window {
    fn newest(&self) -> Option<u64> {
        self.accepted.back().copied()
    }

    /// Whether `counter` is new and within `window_us` of the newest.
    fn admits(&self, counter: u64, window_us: u64) -> bool {
        let Some(newest) = self.newest() else {
            return true;
        };
        if counter > newest {
            return true;
        }
        let floor = newest.saturating_sub(window_us);
        let oldest_kept = self.accepted.front().copied().unwrap_or(0);
        let forgot = self.accepted.len() >= MAX_KEPT && counter < oldest_kept;
        counter >= floor && !forgot && self.accepted.binary_search(&counter).is_err()
    }

    fn accept(&mut self, counter: u64, window_us: u64) {
        let at = self.accepted.partition_point(|&c| c < counter);
        self.accepted.insert(at, counter);
        let floor = self.newest().unwrap_or(0).saturating_sub(window_us);
        while self.accepted.front().is_some_and(|&c| c < floor) || self.accepted.len() > MAX_KEPT {
            self.accepted.pop_front();
        }
    }
}

/// Checks incoming messages: tag, freshness, replays.
#[derive(Debug, Clone)]
pub struct Verifier {
    key: GroupKey,
    freshness: Freshness,
    windows: BTreeMap<String, Window>,
    stats: AuthStats,
}

impl Verifier {
    pub fn new(key: GroupKey, freshness: Freshness) -> Self {
        Self {
            key,
            freshness,
            windows: BTreeMap::new(),
            stats: AuthStats::default(),
        }
    }

    pub fn stats(&self) -> &AuthStats {
        &self.stats
    }

    /// The message of `data` received on `channel` at the receiver's clock
    /// `now_us` (µs since the Unix epoch), without its trailer, or why it is
    /// refused. Either way it is counted.
    pub fn verify<'d>(
        &mut self,
        channel: &str,
        data: &'d [u8],
        now_us: u64,
    ) -> Result<&'d [u8], Refusal> {
        let outcome = self.check(channel, data, now_us);
        let counts = match self.stats.channels.get_mut(channel) {
            Some(counts) => counts,
            // Channel names come from the network: each costs one entry,
            // as the transport's own per-channel counts do.
            None => self.stats.channels.entry(channel.to_owned()).or_default(),
        };
        match outcome {
            Ok(_) => counts.accepted += 1,
            Err(refusal) => {
                counts.refused[refusal.index()] += 1;
            }
        }
        outcome
    }

    fn check<'d>(
        &mut self,
        channel: &str,
        data: &'d [u8],
        now_us: u64,
    ) -> Result<&'d [u8], Refusal> {
        let Some(split) = data.len().checked_sub(TRAILER_LEN) else {
            return Err(Refusal::Unauthenticated);
        };
        let (message, trailer) = data.split_at(split);
        if &trailer[..4] != MAGIC || trailer[4..8] != [0; 4] {
            return Err(Refusal::Unauthenticated);
        }
        let counter = u64::from_be_bytes(trailer[8..16].try_into().unwrap_or_default());
        self.key
            .mac(channel, message, counter)
            .verify_slice(&trailer[16..])
            .map_err(|_| Refusal::BadTag)?;
        let f = self.freshness;
        if counter.saturating_add(f.max_age_us) < now_us {
            return Err(Refusal::Expired);
        }
        if counter > now_us.saturating_add(f.max_skew_us) {
            return Err(Refusal::FromFuture);
        }
        let window = self.windows.entry(channel.to_owned()).or_default();
        if !window.admits(counter, f.window_us) {
            return Err(Refusal::Replayed);
        }
        window.accept(counter, f.window_us);
        Ok(message)
    }
}

/// Which channels carry trailers, and the key: what `[bus.auth]` sets up
/// for a transport ([`crate::transport::Lcm::authenticate`]).
#[derive(Debug, Clone)]
pub struct AuthPolicy {
    key: GroupKey,
    freshness: Freshness,
    channels: Vec<ChannelFilter>,
}

impl AuthPolicy {
    /// `channels` are patterns matched against whole channel names
    /// (`ARC_VOTES_.*`), as LCM subscriptions are.
    pub fn new(
        key: GroupKey,
        freshness: Freshness,
        channels: &[String],
    ) -> Result<Self, regex::Error> {
        let channels = channels
            .iter()
            .map(|pattern| ChannelFilter::pattern(pattern))
            .collect::<Result<_, _>>()?;
        Ok(Self {
            key,
            freshness,
            channels,
        })
    }

    /// Why `pattern` cannot name channels, if it cannot.
    pub fn pattern_error(pattern: &str) -> Option<String> {
        ChannelFilter::pattern(pattern).err().map(|e| e.to_string())
    }

    /// Whether messages on `channel` are signed and verified.
    pub fn covers(&self, channel: &str) -> bool {
        self.channels.iter().any(|filter| filter.matches(channel))
    }

    pub fn signer(&self) -> Signer {
        Signer::new(self.key.clone())
    }

    pub fn verifier(&self) -> Verifier {
        Verifier::new(self.key.clone(), self.freshness)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key() -> GroupKey {
        GroupKey::new(&[7; 32]).unwrap()
    }

    const T: u64 = 1_700_000_000_000_000;

    #[test]
    fn a_signed_message_verifies_once_and_comes_back_without_its_trailer() {
        let mut signer = Signer::new(key());
        let mut verifier = Verifier::new(key(), Freshness::default());
        let sent = signer.sign("STEERING_COMMAND", b"command", T);
        assert_eq!(sent.len(), 7 + TRAILER_LEN);
        assert_eq!(
            verifier.verify("STEERING_COMMAND", &sent, T + 1000),
            Ok(&b"command"[..])
        );
        assert_eq!(
            verifier.verify("STEERING_COMMAND", &sent, T + 2000),
            Err(Refusal::Replayed)
        );
        let counts = verifier.stats().channels["STEERING_COMMAND"];
        assert_eq!((counts.accepted, counts.refused_total()), (1, 1));
    }

    #[test]
    fn tampering_another_key_another_channel_or_no_trailer_is_refused() {
        let mut signer = Signer::new(key());
        let mut verifier = Verifier::new(key(), Freshness::default());
        let sent = signer.sign("STEERING_COMMAND", b"command", T);
        for byte in [0, 6, 7 + 8, 7 + 20, sent.len() - 1] {
            let mut tampered = sent.clone();
            tampered[byte] ^= 1;
            let refusal = verifier
                .verify("STEERING_COMMAND", &tampered, T)
                .unwrap_err();
            assert!(
                matches!(refusal, Refusal::BadTag | Refusal::Unauthenticated),
                "byte {byte}: {refusal}"
            );
        }
        let other =
            Signer::new(GroupKey::new(&[8; 32]).unwrap()).sign("STEERING_COMMAND", b"command", T);
        assert_eq!(
            verifier.verify("STEERING_COMMAND", &other, T),
            Err(Refusal::BadTag)
        );
        assert_eq!(
            verifier.verify("ARC_VOTES_X", &sent, T),
            Err(Refusal::BadTag)
        );
        assert_eq!(
            verifier.verify("STEERING_COMMAND", b"command", T),
            Err(Refusal::Unauthenticated)
        );
        assert_eq!(
            verifier.verify("STEERING_COMMAND", b"", T),
            Err(Refusal::Unauthenticated)
        );
    }

    #[test]
    fn stale_future_and_far_reordered_messages_are_refused_near_reordered_ones_pass() {
        let f = Freshness::default();
        let mut signer = Signer::new(key());
        let mut verifier = Verifier::new(key(), f);
        let old = signer.sign("C", b"a", T);
        assert_eq!(
            verifier.verify("C", &old, T + f.max_age_us + 1),
            Err(Refusal::Expired)
        );
        let ahead = signer.sign("C", b"b", T + f.max_skew_us + 10);
        assert_eq!(verifier.verify("C", &ahead, T), Err(Refusal::FromFuture));
        // Sent 100 ms apart, received out of order: within the 200 ms window.
        let first = Signer::new(key()).sign("D", b"1", T);
        let second = Signer::new(key()).sign("D", b"2", T + 100_000);
        let third = Signer::new(key()).sign("D", b"3", T + 400_000);
        assert!(verifier.verify("D", &second, T + 100_000).is_ok());
        assert!(verifier.verify("D", &first, T + 100_000).is_ok());
        assert!(verifier.verify("D", &third, T + 400_000).is_ok());
        let late = Signer::new(key()).sign("D", b"4", T + 150_000);
        assert_eq!(
            verifier.verify("D", &late, T + 400_000),
            Err(Refusal::Replayed)
        );
        // A signer whose clock stalls still sends distinct counters.
        let mut stalled = Signer::new(key());
        let (x, y) = (stalled.sign("E", b"x", T), stalled.sign("E", b"x", T));
        assert!(verifier.verify("E", &x, T).is_ok() && verifier.verify("E", &y, T).is_ok());
        assert_eq!(verifier.stats().refused_total(), 3);
        assert_eq!(verifier.stats().refusal_lines().len(), 2);
    }

    #[test]
    fn the_window_keeps_a_bounded_number_of_counters_and_only_narrows() {
        let mut window = Window::default();
        for k in 0..(3 * MAX_KEPT as u64) {
            assert!(window.admits(T + k, 1_000_000));
            window.accept(T + k, 1_000_000);
        }
        assert_eq!(window.accepted.len(), MAX_KEPT);
        assert!(!window.admits(T, 1_000_000), "forgotten, so refused");
        assert!(
            !window.admits(T + 3 * MAX_KEPT as u64 - 1, 1_000_000),
            "seen"
        );
    }

    /// The key read from a file of `contents` and `mode`, and the file's
    /// path (the file is gone once the call returns: the error names it).
    fn key_file(contents: &str, mode: u32) -> (PathBuf, Result<GroupKey, KeyError>) {
        use std::os::unix::fs::PermissionsExt;
        let dir = arcnav_testkit::scratch_dir("arcnav-key");
        let path = dir.join("group.key");
        std::fs::write(&path, contents).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
        let key = GroupKey::from_file(&path);
        (path, key)
    }

    #[test]
    fn key_files_must_be_private_hex_and_long_enough_and_errors_name_them() {
        let good = "00112233445566778899aabbccddeeff\n00112233445566778899AABBCCDDEEFF\n";
        let (_, key) = key_file(good, 0o600);
        assert_eq!(key.unwrap().0.len(), 32);
        for (contents, mode, expect) in [
            (good, 0o644, "readable by everyone"),
            (good, 0o640, "readable by its group"),
            ("0011", 0o600, "2-byte key"),
            ("zz", 0o600, "not a hex digit"),
            ("001", 0o600, "odd number"),
        ] {
            let (path, key) = key_file(contents, mode);
            let message = key.unwrap_err().to_string();
            assert!(message.contains(expect), "{message}");
            assert!(message.contains(&path.display().to_string()), "{message}");
        }
        let missing = std::env::temp_dir().join("arcnav-no-such-key-file");
        let message = GroupKey::from_file(&missing).unwrap_err().to_string();
        assert!(
            message.contains("arcnav-no-such-key-file") && message.contains("cannot read"),
            "{message}"
        );
    }
}
