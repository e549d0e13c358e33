//! LCM event logs, as written by `lcm-logger` and read by `lcm-logplayer`.
//!
//! Each event: `u32 sync 0xEDA1DA01, i64 event_number, i64 timestamp_us,
//! i32 channel_len, i32 data_len, channel bytes (no NUL), data`, big-endian.
//!
//! [`LogReader`] streams events with bounded memory and survives damage: a
//! bad sync word or an impossible header makes it scan for the next sync word
//! (the skipped bytes are counted); an event whose declared length runs into
//! what looks like the next event is dropped as corrupt; a log that ends
//! mid-event (a killed logger) ends the stream with the tail counted, not
//! with an error. Only I/O failures are errors.
//!
//! [`LogWriter`] hands every event to the operating system in one `write`
//! before returning (then flushes), so a process that is killed loses no
//! completed event; call [`LogWriter::sync`] to also survive a power loss.

use std::fs::File;
use std::io::{self, Read, Write};
use std::path::Path;

use crate::codec::{EncodeError, Message};

/// Marks the start of every event.
pub const SYNC_WORD: u32 = 0xEDA1_DA01;
const SYNC_BYTES: [u8; 4] = SYNC_WORD.to_be_bytes();
/// Size of an event header.
pub const HEADER_LEN: usize = 28;
/// The reference reader refuses channel names of this length or more.
pub const MAX_CHANNEL_LEN: usize = 1000;
/// Largest event data accepted (the reference's message limit, 2^28 bytes).
pub const MAX_DATA_LEN: usize = 1 << 28;

const MIN_BUFFER: usize = 1 << 16;

/// One event of a log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LogEvent {
    pub event_number: i64,
    /// When the event was logged, µs.
    pub timestamp: i64,
    pub channel: String,
    pub data: Vec<u8>,
}

/// What a reader met on its way through a log.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct LogStats {
    /// Events returned.
    pub events: u64,
    /// Bytes skipped while looking for a sync word.
    pub skipped_bytes: u64,
    /// Times the reader lost and found the event stream again.
    pub resyncs: u64,
    /// Events dropped because their header or length was corrupt.
    pub corrupt_events: u64,
    /// Bytes of an incomplete event at the end of the log (a killed logger).
    pub truncated_tail_bytes: u64,
}

impl LogStats {
    /// True when some of the log could not be read.
    pub fn lost_anything(&self) -> bool {
        self.skipped_bytes > 0 || self.corrupt_events > 0 || self.truncated_tail_bytes > 0
    }
}

/// Streams the events of a log.
pub struct LogReader<R> {
    inner: R,
    buf: Vec<u8>,
    start: usize,
    end: usize,
    eof: bool,
    stats: LogStats,
    /// Bytes of the input consumed so far.
    position: u64,
}

impl LogReader<File> {
    /// Opens a log file.
    pub fn open(path: impl AsRef<Path>) -> io::Result<Self> {
        Ok(Self::new(File::open(path)?))
    }
}

impl<R: Read> LogReader<R> {
    pub fn new(inner: R) -> Self {
        Self {
            inner,
            buf: vec![0; MIN_BUFFER],
            start: 0,
            end: 0,
            eof: false,
            stats: LogStats::default(),
            position: 0,
        }
    }

    pub fn stats(&self) -> &LogStats {
        &self.stats
    }

    /// Bytes of the log consumed so far (for progress).
    pub fn position(&self) -> u64 {
        self.position
    }

    fn available(&self) -> &[u8] {
        &self.buf[self.start..self.end]
    }

    /// Makes at least `n` bytes available unless the input ends first;
    /// returns whether they are.
    fn fill(&mut self, n: usize) -> io::Result<bool> {
        while self.end - self.start < n && !self.eof {
            if self.start > 0 {
                self.buf.copy_within(self.start..self.end, 0);
                self.end -= self.start;
                self.start = 0;
            }
            let want = n.max(MIN_BUFFER);
            if self.buf.len() < want && self.end == self.buf.len() {
                // Grown as the bytes come, not to what a header claims: a
                // damaged length of 256 MiB costs only the bytes that exist.
                let grown = (self.buf.len() * 2).clamp(MIN_BUFFER, want);
                self.buf.resize(grown, 0);
            } else if self.buf.len() > 4 * want && self.end < want {
                // A huge event has passed: give the memory back.
                self.buf.truncate(want);
                self.buf.shrink_to_fit();
            }
            match self.inner.read(&mut self.buf[self.end..]) {
                Ok(0) => self.eof = true,
                Ok(read) => self.end += read,
                Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                Err(e) => return Err(e),
            }
        }
        Ok(self.end - self.start >= n)
    }

    fn consume(&mut self, n: usize) {
        self.start += n;
        self.position += n as u64;
    }

    /// Skips to the next sync word after the first byte, counting what is skipped.
    fn resync(&mut self) -> io::Result<()> {
        self.stats.resyncs += 1;
        self.consume(1);
        self.stats.skipped_bytes += 1;
        loop {
            if let Some(at) = find_sync(self.available()) {
                self.consume(at);
                self.stats.skipped_bytes += at as u64;
                return Ok(());
            }
            // Keep the last 3 bytes: they may start a sync word.
            let keep = self.available().len().min(3);
            let skip = self.available().len() - keep;
            self.consume(skip);
            self.stats.skipped_bytes += skip as u64;
            if !self.fill(keep + 1)? {
                self.stats.skipped_bytes += self.available().len() as u64;
                self.consume(self.available().len());
                return Ok(());
            }
        }
    }

    /// The next event, `None` at the end of the log.
    pub fn next_event(&mut self) -> io::Result<Option<LogEvent>> {
        loop {
            if !self.fill(4)? {
                self.end_of_log();
                return Ok(None);
            }
            if self.available()[..4] != SYNC_BYTES {
                self.resync()?;
                continue;
            }
            if !self.fill(HEADER_LEN)? {
                self.end_of_log();
                return Ok(None);
            }
            let header = &self.available()[..HEADER_LEN];
            let event_number = i64::from_be_bytes(array(&header[4..12]));
            let timestamp = i64::from_be_bytes(array(&header[12..20]));
            let channel_len = i32::from_be_bytes(array(&header[20..24]));
            let data_len = i32::from_be_bytes(array(&header[24..28]));
            let (Ok(channel_len), Ok(data_len)) =
                (usize::try_from(channel_len), usize::try_from(data_len))
            else {
                self.corrupt()?;
                continue;
            };
            if channel_len == 0 || channel_len >= MAX_CHANNEL_LEN || data_len > MAX_DATA_LEN {
                self.corrupt()?;
                continue;
            }
            let total = HEADER_LEN + channel_len + data_len;
            if !self.fill(total)? {
                // Either the logger was killed mid-event, or the length is
                // corrupt and another event starts inside it.
                if hides_event(&self.available()[4..]) {
                    self.corrupt()?;
                    continue;
                }
                self.end_of_log();
                return Ok(None);
            }
            let body = &self.available()[..total];
            let Ok(channel) = std::str::from_utf8(&body[HEADER_LEN..HEADER_LEN + channel_len])
            else {
                self.corrupt()?;
                continue;
            };
            let channel = channel.to_owned();
            // A well-formed event (the next one starts right after it, or the
            // log ends there) is trusted whole, as the reference reader
            // does, whatever its data holds. One that is not, and whose
            // declared span hides another plausible event header, lied about
            // its length: drop it and resynchronise.
            let well_formed = if self.fill(total + 4)? {
                self.available()[total..total + 4] == SYNC_BYTES
            } else {
                self.available().len() == total
            };
            if !well_formed && hides_event(&self.available()[4..total]) {
                self.corrupt()?;
                continue;
            }
            let data = self.available()[HEADER_LEN + channel_len..total].to_vec();
            self.consume(total);
            self.stats.events += 1;
            return Ok(Some(LogEvent {
                event_number,
                timestamp,
                channel,
                data,
            }));
        }
    }

    fn corrupt(&mut self) -> io::Result<()> {
        self.stats.corrupt_events += 1;
        self.resync()
    }

    fn end_of_log(&mut self) {
        let tail = self.available().len();
        if tail > 0 {
            tracing::warn!(
                bytes = tail,
                "log ends in the middle of an event (was the logger killed?)"
            );
            self.stats.truncated_tail_bytes += tail as u64;
            self.consume(tail);
        }
    }
}

impl<R: Read> Iterator for LogReader<R> {
    type Item = io::Result<LogEvent>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_event().transpose()
    }
}

/// Where events come from: a log as written, or put in time order.
pub trait EventSource {
    /// The next event; `None` at the end.
    fn next_event(&mut self) -> io::Result<Option<LogEvent>>;
    /// What the underlying reader met.
    fn stats(&self) -> &LogStats;
    /// Bytes of the log consumed so far (for progress).
    fn position(&self) -> u64;
}

impl<R: Read> EventSource for LogReader<R> {
    fn next_event(&mut self) -> io::Result<Option<LogEvent>> {
        LogReader::next_event(self)
    }

    fn stats(&self) -> &LogStats {
        LogReader::stats(self)
    }

    fn position(&self) -> u64 {
        LogReader::position(self)
    }
}

/// How far [`InTimeOrder`] reads ahead to put events in time order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ReorderWindow {
    /// Events are held until the log has reached this far past them, µs.
    pub horizon_us: i64,
    /// ... or until this many bytes of event data are held.
    pub max_bytes: usize,
    /// ... or this many events.
    pub max_events: usize,
}

impl Default for ReorderWindow {
    /// 30 s of log, at most 64 MiB and 1 M events held.
    fn default() -> Self {
        Self {
            horizon_us: 30_000_000,
            max_bytes: 64 << 20,
            max_events: 1 << 20,
        }
    }
}

/// How a log's order differed from time order.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct OrderStats {
    /// Events that came in the file after an event logged later: put back
    /// in time order.
    pub reordered: u64,
    /// Events further out of order than the window: returned as they came,
    /// after later ones.
    pub beyond_window: u64,
    /// The largest lag of an event behind the latest logged before it, µs.
    pub max_lag_us: i64,
    /// Times a channel went back in time (a log that starts over, logs
    /// concatenated): what came before is returned first, then the new run.
    pub restarts: u64,
}

struct Held(LogEvent, u64);

impl PartialEq for Held {
    fn eq(&self, other: &Self) -> bool {
        (self.0.timestamp, self.1) == (other.0.timestamp, other.1)
    }
}
impl Eq for Held {}
impl PartialOrd for Held {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for Held {
    /// The earliest (then the first read) is the greatest: a max-heap pops it.
    fn cmp(&self, other: &Self) -> std::cmp::Ordering {
        (other.0.timestamp, other.1).cmp(&(self.0.timestamp, self.1))
    }
}

/// The events of a log in the order of their timestamps, as far as a
/// bounded window allows. LCM logs are usually written in time order, but
/// nothing requires it: a log merged from several, or written by a program
/// that logs each channel in batches, is not, and played as written its
/// events arrive late. Within the window, events equal in time keep their
/// order in the file; a log already in order comes out unchanged.
///
/// One channel's events are taken to be in the order they were logged:
/// only between channels may the file be out of order. An event older than
/// the previous one of its own channel (or as old, when the log has moved
/// on since) starts the log over (two logs concatenated, a clock reset):
/// everything before it is returned first.
pub struct InTimeOrder<S> {
    source: S,
    window: ReorderWindow,
    held: std::collections::BinaryHeap<Held>,
    held_bytes: usize,
    read: u64,
    newest_read: Option<i64>,
    newest_returned: Option<i64>,
    /// The newest time of each channel (at most [`MAX_TRACKED_CHANNELS`]).
    channels: std::collections::HashMap<String, i64>,
    /// The first event of a new run, waiting until the old one is out.
    restart: Option<LogEvent>,
    ended: bool,
    order: OrderStats,
}

/// Channels whose own order [`InTimeOrder`] follows; a log with more
/// (damage, or a generator of names) has the rest reordered without it.
const MAX_TRACKED_CHANNELS: usize = 4096;

impl<S: EventSource> InTimeOrder<S> {
    pub fn new(source: S, window: ReorderWindow) -> Self {
        Self {
            source,
            window,
            held: std::collections::BinaryHeap::new(),
            held_bytes: 0,
            read: 0,
            newest_read: None,
            newest_returned: None,
            channels: std::collections::HashMap::new(),
            restart: None,
            ended: false,
            order: OrderStats::default(),
        }
    }

    /// Takes `event` into the window.
    fn hold(&mut self, event: LogEvent) {
        let t = event.timestamp;
        if let Some(newest) = self.newest_read
            && t < newest
        {
            self.order.reordered += 1;
            self.order.max_lag_us = self.order.max_lag_us.max(newest - t);
            if self.newest_returned.is_some_and(|r| t < r) {
                self.order.beyond_window += 1;
            }
        }
        self.newest_read = Some(self.newest_read.map_or(t, |n| n.max(t)));
        self.held_bytes += event.data.len();
        self.held.push(Held(event, self.read));
        self.read += 1;
    }

    /// True when `event` is older than its channel's previous event, or as
    /// old while the log has moved on since (the same event again).
    fn starts_over(&mut self, event: &LogEvent) -> bool {
        let t = event.timestamp;
        let moved_on = self.newest_read.is_some_and(|n| t < n);
        match self.channels.get_mut(&event.channel) {
            Some(last) if t < *last || (t == *last && moved_on) => true,
            Some(last) => {
                *last = t;
                false
            }
            None => {
                if self.channels.len() < MAX_TRACKED_CHANNELS {
                    self.channels.insert(event.channel.clone(), t);
                }
                false
            }
        }
    }

    pub fn order(&self) -> &OrderStats {
        &self.order
    }

    /// Where the events come from.
    pub fn source(&self) -> &S {
        &self.source
    }

    fn must_release(&self) -> bool {
        let (Some(earliest), Some(newest)) = (self.held.peek(), self.newest_read) else {
            return false;
        };
        self.ended
            || self.restart.is_some()
            || self.held_bytes >= self.window.max_bytes
            || self.held.len() >= self.window.max_events
            || newest.saturating_sub(earliest.0.timestamp) > self.window.horizon_us
    }
}

impl<S: EventSource> EventSource for InTimeOrder<S> {
    fn next_event(&mut self) -> io::Result<Option<LogEvent>> {
        if self.held.is_empty()
            && let Some(first) = self.restart.take()
        {
            // The old run is out: the new one starts afresh.
            self.order.restarts += 1;
            self.channels.clear();
            self.newest_read = None;
            self.newest_returned = None;
            self.starts_over(&first);
            self.hold(first);
        }
        while self.restart.is_none() && !self.ended && !self.must_release() {
            match self.source.next_event()? {
                Some(event) if self.starts_over(&event) => self.restart = Some(event),
                Some(event) => self.hold(event),
                None => self.ended = true,
            }
        }
        let Some(Held(event, _)) = self.held.pop() else {
            return Ok(None);
        };
        self.held_bytes -= event.data.len();
        self.newest_returned = Some(
            self.newest_returned
                .map_or(event.timestamp, |r| r.max(event.timestamp)),
        );
        Ok(Some(event))
    }

    fn stats(&self) -> &LogStats {
        self.source.stats()
    }

    fn position(&self) -> u64 {
        self.source.position()
    }
}

impl<S: EventSource> Iterator for InTimeOrder<S> {
    type Item = io::Result<LogEvent>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_event().transpose()
    }
}

/// Plays the events of `log` whose channel `keep` accepts at `speed` × the
/// pace they were logged at, handing each to `publish` on time (what
/// `lcm-logplayer` does, for feeding an LCM instance in-process), in file
/// order (put it [`InTimeOrder`] first to play it in time order). Returns
/// the number of events played.
pub fn play(
    log: impl Iterator<Item = io::Result<LogEvent>>,
    speed: f64,
    keep: impl Fn(&str) -> bool,
    mut publish: impl FnMut(&LogEvent),
) -> io::Result<u64> {
    let started = std::time::Instant::now();
    let mut first = None;
    let mut played = 0;
    for event in log {
        let event = event?;
        if !keep(&event.channel) {
            continue;
        }
        let t0 = *first.get_or_insert(event.timestamp);
        let due = (event.timestamp - t0).max(0) as f64 * 1e-6 / speed;
        if let Some(wait) = std::time::Duration::from_secs_f64(due).checked_sub(started.elapsed()) {
            std::thread::sleep(wait);
        }
        publish(&event);
        played += 1;
    }
    Ok(played)
}

fn array<const N: usize>(bytes: &[u8]) -> [u8; N] {
    let mut out = [0u8; N];
    out.copy_from_slice(&bytes[..N]);
    out
}

fn find_sync(bytes: &[u8]) -> Option<usize> {
    memchr::memmem::find(bytes, &SYNC_BYTES)
}

/// True when `bytes` contain a sync word followed by a header that could
/// start a real event (sane lengths, printable channel name). Random data
/// matches with odds far below one in 2^50 per position.
fn hides_event(bytes: &[u8]) -> bool {
    let mut from = 0;
    while let Some(at) = find_sync(&bytes[from..]) {
        let at = from + at;
        if let Some(header) = bytes.get(at..at + HEADER_LEN) {
            let channel_len = i32::from_be_bytes(array(&header[20..24]));
            let data_len = i32::from_be_bytes(array(&header[24..28]));
            let sane = (1..MAX_CHANNEL_LEN as i32).contains(&channel_len) && data_len >= 0;
            if sane {
                let channel = &bytes[at + HEADER_LEN..];
                let channel = &channel[..channel.len().min(channel_len as usize)];
                if !channel.is_empty() && channel.iter().all(|b| b.is_ascii_graphic()) {
                    return true;
                }
            }
        }
        from = at + 1;
    }
    false
}

/// An event that cannot be written.
#[derive(Debug, thiserror::Error)]
pub enum LogWriteError {
    #[error("cannot write the log: {0}")]
    Io(#[from] io::Error),
    #[error("channel name {channel:?} must be 1 to {} bytes", MAX_CHANNEL_LEN - 1)]
    BadChannel { channel: String },
    #[error("event of {len} bytes is larger than the {MAX_DATA_LEN} bytes a log event may hold")]
    TooLarge { len: usize },
    #[error("cannot encode the message: {0}")]
    Encode(#[from] EncodeError),
}

/// Appends events to a log.
pub struct LogWriter<W: Write> {
    inner: W,
    next_event_number: i64,
    event: Vec<u8>,
    message: Vec<u8>,
}

impl LogWriter<File> {
    /// Creates (or truncates) a log file.
    pub fn create(path: impl AsRef<Path>) -> io::Result<Self> {
        Ok(Self::new(File::create(path)?))
    }

    /// Asks the operating system to put everything written on disk.
    pub fn sync(&mut self) -> io::Result<()> {
        self.inner.sync_data()
    }
}

impl<W: Write> LogWriter<W> {
    pub fn new(inner: W) -> Self {
        Self {
            inner,
            next_event_number: 0,
            event: Vec::new(),
            message: Vec::new(),
        }
    }

    /// Writes one event and returns its event number; the event is with the
    /// operating system when this returns.
    pub fn write_event(
        &mut self,
        timestamp: i64,
        channel: &str,
        data: &[u8],
    ) -> Result<i64, LogWriteError> {
        if channel.is_empty() || channel.len() >= MAX_CHANNEL_LEN {
            return Err(LogWriteError::BadChannel {
                channel: channel.to_owned(),
            });
        }
        if data.len() > MAX_DATA_LEN {
            return Err(LogWriteError::TooLarge { len: data.len() });
        }
        let number = self.next_event_number;
        self.event.clear();
        self.event.extend_from_slice(&SYNC_BYTES);
        self.event.extend_from_slice(&number.to_be_bytes());
        self.event.extend_from_slice(&timestamp.to_be_bytes());
        // Both lengths are bounded above, far below i32::MAX.
        self.event
            .extend_from_slice(&(channel.len() as i32).to_be_bytes());
        self.event
            .extend_from_slice(&(data.len() as i32).to_be_bytes());
        self.event.extend_from_slice(channel.as_bytes());
        self.event.extend_from_slice(data);
        self.inner.write_all(&self.event)?;
        self.inner.flush()?;
        self.next_event_number += 1;
        Ok(number)
    }

    /// Encodes `message` and writes it as one event.
    pub fn write_message<M: Message>(
        &mut self,
        timestamp: i64,
        channel: &str,
        message: &M,
    ) -> Result<i64, LogWriteError> {
        let mut encoded = std::mem::take(&mut self.message);
        let result = message
            .encode_into(&mut encoded)
            .map_err(LogWriteError::from)
            .and_then(|()| self.write_event(timestamp, channel, &encoded));
        self.message = encoded;
        result
    }

    /// Number of events written so far.
    pub fn events_written(&self) -> i64 {
        self.next_event_number
    }

    pub fn into_inner(self) -> W {
        self.inner
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn log_of(events: &[(i64, &str, &[u8])]) -> Vec<u8> {
        let mut writer = LogWriter::new(Vec::new());
        for (t, channel, data) in events {
            writer.write_event(*t, channel, data).unwrap();
        }
        writer.into_inner()
    }

    fn read_all(bytes: &[u8]) -> (Vec<LogEvent>, LogStats) {
        let mut reader = LogReader::new(bytes);
        let events = reader.by_ref().collect::<io::Result<Vec<_>>>().unwrap();
        (events, *reader.stats())
    }

    #[test]
    fn events_round_trip_with_numbers_and_timestamps() {
        let bytes = log_of(&[(10, "POSE", b"abc"), (20, "RANGE_IMAGE", &[0u8; 100_000])]);
        assert_eq!(&bytes[..4], &[0xED, 0xA1, 0xDA, 0x01]);
        let (events, stats) = read_all(&bytes);
        assert_eq!(events.len(), 2);
        assert_eq!((events[0].event_number, events[0].timestamp), (0, 10));
        assert_eq!(events[0].channel, "POSE");
        assert_eq!(events[0].data, b"abc");
        assert_eq!(events[1].event_number, 1);
        assert_eq!(events[1].data.len(), 100_000);
        assert!(!stats.lost_anything());
    }

    #[test]
    fn a_truncated_last_event_is_counted_not_an_error() {
        let bytes = log_of(&[(1, "A", b"0123456789"), (2, "B", b"0123456789")]);
        let cut = &bytes[..bytes.len() - 4];
        let (events, stats) = read_all(cut);
        assert_eq!(events.len(), 1);
        assert_eq!(stats.truncated_tail_bytes, (HEADER_LEN + 1 + 10 - 4) as u64);
        assert!(stats.lost_anything());
    }

    #[test]
    fn garbage_between_events_is_skipped_and_counted() {
        let first = log_of(&[(1, "A", b"xy")]);
        let mut second = log_of(&[(2, "B", b"zw")]);
        second[4..12].copy_from_slice(&1i64.to_be_bytes());
        let mut bytes = first.clone();
        bytes.extend_from_slice(&[0x55; 17]);
        bytes.extend_from_slice(&second);
        let (events, stats) = read_all(&bytes);
        assert_eq!(
            events
                .iter()
                .map(|e| e.channel.as_str())
                .collect::<Vec<_>>(),
            ["A", "B"]
        );
        assert_eq!(stats.skipped_bytes, 17);
        assert_eq!(stats.resyncs, 1);
    }

    #[test]
    fn an_event_with_a_lying_length_is_dropped_and_the_next_one_found() {
        let mut bytes = log_of(&[(1, "A", b"first"), (2, "B", b"second"), (3, "C", b"third")]);
        // Corrupt A's data length so that it swallows B and ends inside C
        // (a length that ended exactly on C's sync word would make A a
        // well-formed event holding B's bytes: trusted, as the reference does).
        bytes[24..28].copy_from_slice(&41i32.to_be_bytes());
        let (events, stats) = read_all(&bytes);
        let channels: Vec<_> = events.iter().map(|e| e.channel.as_str()).collect();
        assert_eq!(channels, ["B", "C"]);
        assert_eq!(stats.corrupt_events, 1);
        assert!(stats.skipped_bytes > 0);
    }

    #[test]
    fn a_valid_event_whose_data_holds_a_sync_word_and_a_header_is_read_whole() {
        // A range image's bytes may hold anything, an event header included.
        let inner = log_of(&[(5, "RANGE_IMAGE", b"payload")]);
        let mut data = vec![7u8; 100];
        data.extend_from_slice(&inner);
        data.extend_from_slice(&[9u8; 100]);
        let bytes = log_of(&[
            (1, "POSE", b"p"),
            (2, "RANGE_IMAGE", &data),
            (3, "POSE", b"q"),
        ]);
        let (events, stats) = read_all(&bytes);
        assert_eq!(events.len(), 3);
        assert_eq!(events[1].data, data);
        assert_eq!(stats.skipped_bytes, 0);
        assert_eq!(stats.corrupt_events, 0);
        // As the last event of the log too.
        let bytes = log_of(&[(1, "POSE", b"p"), (2, "RANGE_IMAGE", &data)]);
        let (events, stats) = read_all(&bytes);
        assert_eq!((events.len(), stats.skipped_bytes), (2, 0));
    }

    #[test]
    fn impossible_headers_are_skipped() {
        let mut bytes = log_of(&[(1, "A", b"1"), (2, "B", b"2")]);
        bytes[20..24].copy_from_slice(&(-5i32).to_be_bytes());
        let (events, stats) = read_all(&bytes);
        assert_eq!(events.len(), 1);
        assert_eq!(events[0].channel, "B");
        assert_eq!(stats.corrupt_events, 1);
    }

    #[test]
    fn only_garbage_yields_nothing_and_counts_everything() {
        let (events, stats) = read_all(&[7u8; 1000]);
        assert!(events.is_empty());
        assert_eq!(stats.skipped_bytes, 1000);
        let (events, _) = read_all(&[]);
        assert!(events.is_empty());
    }

    #[test]
    fn bad_channels_are_refused_by_the_writer() {
        let mut writer = LogWriter::new(Vec::new());
        assert!(matches!(
            writer.write_event(0, "", b""),
            Err(LogWriteError::BadChannel { .. })
        ));
        let long = "X".repeat(1000);
        assert!(matches!(
            writer.write_event(0, &long, b""),
            Err(LogWriteError::BadChannel { .. })
        ));
        assert_eq!(writer.events_written(), 0);
    }

    #[test]
    fn reads_one_byte_at_a_time_like_a_slow_pipe() {
        struct Trickle<'a>(&'a [u8]);
        impl Read for Trickle<'_> {
            fn read(&mut self, out: &mut [u8]) -> io::Result<usize> {
                let Some((first, rest)) = self.0.split_first() else {
                    return Ok(0);
                };
                out[0] = *first;
                self.0 = rest;
                Ok(1)
            }
        }
        let bytes = log_of(&[(1, "A", b"hello"), (2, "B", &[9u8; 70_000])]);
        let events: Vec<_> = LogReader::new(Trickle(&bytes))
            .collect::<io::Result<_>>()
            .unwrap();
        assert_eq!(events.len(), 2);
        assert_eq!(events[1].data.len(), 70_000);
    }

    #[test]
    fn play_keeps_the_pace_and_the_chosen_channels() {
        let mut writer = LogWriter::new(Vec::new());
        for (t, channel) in [(0, "A"), (100_000, "B"), (200_000, "A"), (400_000, "A")] {
            writer.write_event(1_000_000 + t, channel, &[1, 2]).unwrap();
        }
        let bytes = writer.into_inner();
        let started = std::time::Instant::now();
        let mut seen = Vec::new();
        let played = play(
            LogReader::new(&bytes[..]),
            2.0,
            |c| c == "A",
            |e| {
                seen.push((e.timestamp, started.elapsed()));
            },
        )
        .unwrap();
        assert_eq!(played, 3);
        assert_eq!(
            seen.iter().map(|s| s.0).collect::<Vec<_>>(),
            [1_000_000, 1_200_000, 1_400_000]
        );
        // At twice the pace, the last event (0.4 s in) comes after 0.2 s.
        assert!(seen[2].1 >= std::time::Duration::from_millis(200));
    }

    /// Events at these log times on these channels, in this file order.
    fn log_at(events: &[(i64, &str)]) -> Vec<u8> {
        let mut writer = LogWriter::new(Vec::new());
        for &(t, channel) in events {
            writer.write_event(t, channel, &t.to_be_bytes()).unwrap();
        }
        writer.into_inner()
    }

    fn in_order(bytes: &[u8], window: ReorderWindow) -> (Vec<i64>, OrderStats) {
        let mut ordered = InTimeOrder::new(LogReader::new(bytes), window);
        let times = ordered.by_ref().map(|e| e.unwrap().timestamp).collect();
        (times, *ordered.order())
    }

    #[test]
    fn channels_out_of_time_order_with_each_other_come_out_in_time_order() {
        let bytes = log_at(&[
            (0, "A"),
            (20, "A"),
            (40, "A"),
            (10, "B"),
            (60, "A"),
            (30, "B"),
            (80, "A"),
            (50, "B"),
        ]);
        let (times, order) = in_order(&bytes, ReorderWindow::default());
        assert_eq!(times, [0, 10, 20, 30, 40, 50, 60, 80]);
        assert_eq!(order.reordered, 3);
        assert_eq!(order.max_lag_us, 30);
        assert_eq!((order.beyond_window, order.restarts), (0, 0));
        // A log in order comes out as it is, equal times in file order.
        let bytes = log_at(&[(0, "A"), (5, "A"), (5, "B"), (9, "A")]);
        let mut ordered = InTimeOrder::new(LogReader::new(&bytes[..]), ReorderWindow::default());
        let events: Vec<LogEvent> = ordered.by_ref().map(Result::unwrap).collect();
        let plain: Vec<LogEvent> = LogReader::new(&bytes[..]).map(Result::unwrap).collect();
        assert_eq!(events, plain);
        assert_eq!(*ordered.order(), OrderStats::default());
    }

    #[test]
    fn a_log_that_starts_over_is_two_runs_not_one_interleaved() {
        // The same log twice (`cat log log`): each channel goes back in time.
        let run = [(0, "A"), (10, "B"), (20, "A"), (30, "B")];
        let twice: Vec<(i64, &str)> = run.iter().chain(&run).copied().collect();
        let (times, order) = in_order(&log_at(&twice), ReorderWindow::default());
        assert_eq!(times, [0, 10, 20, 30, 0, 10, 20, 30]);
        assert_eq!(order.restarts, 1);
        assert_eq!((order.reordered, order.beyond_window), (0, 0));
    }

    #[test]
    fn events_further_out_of_order_than_the_window_are_counted_and_come_late() {
        // 100 events 1 s apart, then one of another channel logged at 2 s: 98 s late.
        let mut events: Vec<(i64, &str)> = (0..100).map(|k| (k * 1_000_000, "A")).collect();
        events.push((2_000_000, "B"));
        let window = ReorderWindow {
            horizon_us: 10_000_000,
            ..ReorderWindow::default()
        };
        let (out, order) = in_order(&log_at(&events), window);
        assert_eq!(out.len(), 101, "nothing is lost");
        assert_eq!(order.beyond_window, 1);
        assert_eq!(order.max_lag_us, 97_000_000);
        // The held events are bounded by count (and bytes) too.
        let window = ReorderWindow {
            max_events: 4,
            ..ReorderWindow::default()
        };
        let events = [
            (10, "A"),
            (20, "A"),
            (30, "A"),
            (40, "A"),
            (50, "A"),
            (60, "A"),
            (5, "B"),
        ];
        let (out, order) = in_order(&log_at(&events), window);
        assert_eq!(out, [10, 20, 30, 5, 40, 50, 60]);
        assert_eq!(order.beyond_window, 1);
    }
}
