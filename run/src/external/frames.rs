//! The framing of LCM messages over an external behaviour's standard input
//! and output: each message is
//!
//! ```text
//! u32 BE channel length · channel (UTF-8) · u32 BE payload length · payload (LCM-encoded)
//! ```
//!
//! the channel and payload as they would be on the bus (`LOCAL_MAP` with a
//! `local_map_t`, `ARC_VOTES_<NAME>` with an `arc_votes_t`, ...), so a
//! program's code sees the same messages over a pipe as over LCM
//! (`examples/python/arcnav_behaviour.py` hides which).

use std::io::{self, Read, Write};

/// The longest channel name a frame may carry, bytes.
pub const MAX_CHANNEL: usize = 256;
/// The largest payload a frame may carry, bytes (a local map with the
/// elevation layer is ~0.4 MB).
pub const MAX_PAYLOAD: usize = 64 << 20;

/// One framed message.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    pub channel: String,
    pub payload: Vec<u8>,
}

/// A stream that is not a sequence of frames.
#[derive(Debug, thiserror::Error)]
pub enum FrameError {
    #[error("a frame's channel name is {0} bytes long (at most {MAX_CHANNEL})")]
    ChannelTooLong(u32),
    #[error("a frame's channel name is not UTF-8")]
    ChannelNotText,
    #[error("a frame on {channel} says its payload is {len} bytes (at most {MAX_PAYLOAD})")]
    PayloadTooLarge { channel: String, len: u32 },
    #[error("the stream ended inside a frame")]
    Truncated,
    #[error(transparent)]
    Io(#[from] io::Error),
}

/// Appends `channel` and `payload` as one frame to `out`.
pub fn encode(channel: &str, payload: &[u8], out: &mut Vec<u8>) {
    // Both lengths are ours and small (a channel name, an encoded message
    // under MAX_PAYLOAD): they fit in 32 bits.
    out.extend_from_slice(&(channel.len() as u32).to_be_bytes());
    out.extend_from_slice(channel.as_bytes());
    out.extend_from_slice(&(payload.len() as u32).to_be_bytes());
    out.extend_from_slice(payload);
}

/// Writes one frame.
pub fn write(mut w: impl Write, channel: &str, payload: &[u8]) -> io::Result<()> {
    let mut buf = Vec::with_capacity(8 + channel.len() + payload.len());
    encode(channel, payload, &mut buf);
    w.write_all(&buf)
}

/// Reads the next frame; `Ok(None)` at the end of the stream between frames.
/// Lengths are checked before anything is allocated.
pub fn read(mut r: impl Read) -> Result<Option<Frame>, FrameError> {
    let mut len = [0u8; 4];
    match read_exact_or_end(&mut r, &mut len)? {
        Filled::End => return Ok(None),
        Filled::Partial => return Err(FrameError::Truncated),
        Filled::Full => {}
    }
    let channel_len = u32::from_be_bytes(len);
    if channel_len as usize > MAX_CHANNEL {
        return Err(FrameError::ChannelTooLong(channel_len));
    }
    let mut channel = vec![0u8; channel_len as usize];
    full(&mut r, &mut channel)?;
    let channel = String::from_utf8(channel).map_err(|_| FrameError::ChannelNotText)?;
    full(&mut r, &mut len)?;
    let payload_len = u32::from_be_bytes(len);
    if payload_len as usize > MAX_PAYLOAD {
        return Err(FrameError::PayloadTooLarge {
            channel,
            len: payload_len,
        });
    }
    let mut payload = vec![0u8; payload_len as usize];
    full(&mut r, &mut payload)?;
    Ok(Some(Frame { channel, payload }))
}

enum Filled {
    Full,
    Partial,
    End,
}

fn read_exact_or_end(r: &mut impl Read, buf: &mut [u8]) -> io::Result<Filled> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) if got == 0 => return Ok(Filled::End),
            Ok(0) => return Ok(Filled::Partial),
            Ok(n) => got += n,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(Filled::Full)
}

fn full(r: &mut impl Read, buf: &mut [u8]) -> Result<(), FrameError> {
    match read_exact_or_end(r, buf)? {
        Filled::Full => Ok(()),
        Filled::Partial | Filled::End if buf.is_empty() => Ok(()),
        Filled::Partial | Filled::End => Err(FrameError::Truncated),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frames_round_trip_and_a_stream_ends_between_frames() {
        let mut buf = Vec::new();
        encode("LOCAL_MAP", b"abc", &mut buf);
        encode("ARC_VOTES_X", b"", &mut buf);
        let mut r = buf.as_slice();
        let a = read(&mut r).unwrap().unwrap();
        assert_eq!(
            (a.channel.as_str(), a.payload.as_slice()),
            ("LOCAL_MAP", &b"abc"[..])
        );
        let b = read(&mut r).unwrap().unwrap();
        assert_eq!((b.channel.as_str(), b.payload.len()), ("ARC_VOTES_X", 0));
        assert!(read(&mut r).unwrap().is_none());
    }

    #[test]
    fn garbage_is_refused_before_anything_is_allocated() {
        // "hello world\n" as a frame: a channel length of 1.7 GB.
        let err = read(&b"hello world\n"[..]).unwrap_err();
        assert!(matches!(err, FrameError::ChannelTooLong(_)), "{err}");
        let mut buf = Vec::new();
        buf.extend_from_slice(&3u32.to_be_bytes());
        buf.extend_from_slice(b"ABC");
        buf.extend_from_slice(&u32::MAX.to_be_bytes());
        let err = read(buf.as_slice()).unwrap_err();
        assert!(matches!(err, FrameError::PayloadTooLarge { .. }), "{err}");
        let mut cut = Vec::new();
        encode("POSE", b"0123456789", &mut cut);
        cut.truncate(cut.len() - 3);
        assert!(matches!(
            read(cut.as_slice()).unwrap_err(),
            FrameError::Truncated
        ));
        assert!(matches!(
            read(&[0u8, 0][..]).unwrap_err(),
            FrameError::Truncated
        ));
        let mut bad = Vec::new();
        encode("\u{0}", b"", &mut bad);
        bad[4] = 0xff;
        assert!(matches!(
            read(bad.as_slice()).unwrap_err(),
            FrameError::ChannelNotText
        ));
    }
}
