//! # arcnav-bus
//!
//! LCM for arcnav, in pure Rust and wire-compatible with the reference
//! implementation (`lcm-gen`, `lcm-logger`, `lcm-logplayer`, the C and
//! Python bindings):
//!
//! - [`lcmtypes`]: the message types, generated at build time from
//!   `bus/lcmtypes/*.lcm` with the fingerprints `lcm-gen` computes
//!   ([`schema`] is the parser and hash);
//! - [`codec`]: bounded, panic-free encoding and decoding;
//! - [`log`]: LCM event logs, read in a stream that survives corruption and
//!   written so that no completed event is lost;
//! - [`messages`]: decoding by fingerprint into [`messages::AnyMessage`], the
//!   channel names, and conversions to the vehicle crate's types;
//! - [`transport`][]: `udpm://` (UDP multicast, `LC02` and fragmented `LC03`)
//!   and in-process `memq://`;
//! - [`auth`]: a group key, HMAC-SHA256 trailers and the checks that refuse
//!   forged, replayed and stale messages.

pub mod auth;
pub mod channels;
pub mod codec;
pub mod lcmtypes;
pub mod log;
pub mod messages;
pub mod schema;
pub mod transport;

pub use codec::{DecodeError, EncodeError, Message};
pub use log::{LogEvent, LogReader, LogStats, LogWriter};
pub use messages::{AnyMessage, TypedEvent, TypedEvents};
pub use transport::{Lcm, ReceivedMessage};
