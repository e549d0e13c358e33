//! Publishing and receiving LCM messages.
//!
//! ```no_run
//! use arcnav_bus::transport::Lcm;
//! use std::time::Duration;
//!
//! let mut lcm = Lcm::new("udpm://239.255.76.67:7667?ttl=0")?;
//! lcm.subscribe("POSE");
//! lcm.subscribe_regex("ARC_VOTES_.*")?;
//! lcm.publish("STEERING_COMMAND", b"...")?;
//! while let Some(message) = lcm.recv_timeout(Duration::from_millis(100))? {
//!     println!("{} ({} bytes)", message.channel, message.data.len());
//! }
//! # Ok::<(), arcnav_bus::transport::TransportError>(())
//! ```
//!
//! [`Lcm::publisher`] hands out a cloneable, thread-safe [`Publisher`] so
//! several threads can publish while one receives.

pub mod udpm;
pub mod url;

use std::collections::VecDeque;
use std::io;
use std::net::{Ipv4Addr, SocketAddr, SocketAddrV4, UdpSocket};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use socket2::{Domain, Protocol, Socket, Type};

use crate::auth::{AuthPolicy, AuthStats, Refusal, Signer, Verifier};
pub use crate::channels::ChannelFilter;
use crate::codec::{EncodeError, Message};
use udpm::{MAX_CHANNEL_LEN, MAX_MESSAGE_SIZE, Reassembler, ReassemblyStats};
pub use url::{DEFAULT_URL, LcmUrl, UdpmUrl, UrlError};

/// Receive buffer asked of the kernel when the URL does not say (a
/// 128×2048 range image is 1 MiB).
pub const DEFAULT_RECV_BUF_SIZE: usize = 8 << 20;

/// A transport failure.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    #[error(transparent)]
    Url(#[from] UrlError),
    #[error("{action}: {source}")]
    Io { action: String, source: io::Error },
    #[error("channel name {channel:?} is {} bytes; LCM allows 1 to {MAX_CHANNEL_LEN}", channel.len())]
    BadChannel { channel: String },
    #[error("message of {len} bytes is larger than LCM's limit of {MAX_MESSAGE_SIZE} bytes")]
    MessageTooLarge { len: usize },
    #[error("channel pattern {pattern:?} is not a regular expression: {reason}")]
    BadPattern { pattern: String, reason: String },
    #[error("cannot encode the message: {0}")]
    Encode(#[from] EncodeError),
}

fn io_error(action: impl Into<String>) -> impl FnOnce(io::Error) -> TransportError {
    let action = action.into();
    move |source| TransportError::Io { action, source }
}

/// A message as received.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReceivedMessage {
    pub channel: String,
    pub data: Vec<u8>,
    /// Wall-clock time of reception, µs since the Unix epoch.
    pub recv_utime: i64,
}

/// Identifies a subscription, to remove it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct SubscriptionId(u64);

struct Memq {
    queue: Mutex<VecDeque<(String, Vec<u8>)>>,
    ready: Condvar,
}

enum Sender {
    Udpm {
        socket: UdpSocket,
        destination: SocketAddrV4,
        seqno: AtomicU32,
    },
    Memq(Arc<Memq>),
}

/// Publishes on the `Lcm` it came from; cheap to clone, usable from any thread.
#[derive(Clone)]
pub struct Publisher {
    sender: Arc<Sender>,
    /// Signs messages on the channels the policy covers.
    auth: Option<Arc<(AuthPolicy, Mutex<Signer>)>>,
}

impl Publisher {
    /// Publishes raw bytes on `channel`.
    pub fn publish(&self, channel: &str, data: &[u8]) -> Result<(), TransportError> {
        if channel.is_empty() || channel.len() > MAX_CHANNEL_LEN || channel.contains('\0') {
            return Err(TransportError::BadChannel {
                channel: channel.to_owned(),
            });
        }
        let signed;
        let data = match &self.auth {
            Some(auth) if auth.0.covers(channel) => {
                let mut signer = auth.1.lock().unwrap_or_else(|e| e.into_inner());
                let now = u64::try_from(wall_clock_utime()).unwrap_or(0);
                signed = signer.sign(channel, data, now);
                &signed[..]
            }
            _ => data,
        };
        if data.len() > MAX_MESSAGE_SIZE {
            return Err(TransportError::MessageTooLarge { len: data.len() });
        }
        match &*self.sender {
            Sender::Udpm {
                socket,
                destination,
                seqno,
            } => {
                let seqno = seqno.fetch_add(1, Ordering::Relaxed);
                udpm::for_each_datagram(seqno, channel, data, |datagram| {
                    socket.send_to(datagram, *destination).map(drop)
                })
                .map_err(io_error(format!(
                    "cannot send to {destination} (is there a multicast route? e.g. `ip route add 224.0.0.0/4 dev lo`)"
                )))
            }
            Sender::Memq(memq) => {
                let mut queue = memq.queue.lock().unwrap_or_else(|e| e.into_inner());
                queue.push_back((channel.to_owned(), data.to_vec()));
                memq.ready.notify_all();
                Ok(())
            }
        }
    }

    /// Encodes `message` and publishes it on `channel`.
    pub fn publish_message<M: Message>(
        &self,
        channel: &str,
        message: &M,
    ) -> Result<(), TransportError> {
        self.publish(channel, &message.encode()?)
    }

    /// Publishes a command on `channel` in the type `kinematics` calls for
    /// (see [`crate::AnyMessage::command`]).
    pub fn publish_command(
        &self,
        channel: &str,
        command: &arcnav_vehicle::SteeringCommand,
        kinematics: arcnav_vehicle::Kinematics,
    ) -> Result<(), TransportError> {
        self.publish(
            channel,
            &crate::AnyMessage::command(command, kinematics).encode()?,
        )
    }

    /// The UDP port this publisher sends from (`None` for `memq://`).
    pub fn source_port(&self) -> Option<u16> {
        match &*self.sender {
            Sender::Udpm { socket, .. } => socket.local_addr().ok().map(|a| a.port()),
            Sender::Memq(_) => None,
        }
    }
}

enum Receiver {
    Udpm {
        socket: UdpSocket,
        buffer: Vec<u8>,
        reassembler: Reassembler,
    },
    Memq(Arc<Memq>),
    None,
}

/// An LCM instance: a publisher plus a receiver with its subscriptions.
pub struct Lcm {
    url: LcmUrl,
    publisher: Publisher,
    receiver: Receiver,
    subscriptions: Vec<(SubscriptionId, ChannelFilter)>,
    next_id: u64,
    /// Messages received on no subscribed channel.
    unsubscribed: u64,
    /// Checks messages on the channels the policy covers.
    verifier: Option<(AuthPolicy, Verifier)>,
    /// This process's senders whose datagrams are not heard
    /// ([`Lcm::ignore_from`]), and what was dropped for it.
    own: OwnSenders,
}

/// Sending ports of this process, and whether addresses are this host's.
#[derive(Default)]
struct OwnSenders {
    ports: Vec<u16>,
    local: Vec<(std::net::IpAddr, bool)>,
    dropped: u64,
}

impl OwnSenders {
    /// Whether a datagram from `from` was sent by one of the senders: from
    /// one of their ports and from an address of this host (one a socket
    /// can be bound to; no other process holds the port).
    fn sent(&mut self, from: SocketAddr) -> bool {
        if !self.ports.contains(&from.port()) {
            return false;
        }
        let ip = from.ip();
        if let Some(&(_, local)) = self.local.iter().find(|(a, _)| *a == ip) {
            return local;
        }
        let local = UdpSocket::bind((ip, 0)).is_ok();
        self.local.push((ip, local));
        local
    }
}

impl Lcm {
    /// Opens the provider named by `url` (empty: the reference default).
    pub fn new(url: &str) -> Result<Self, TransportError> {
        let parsed: LcmUrl = url.parse()?;
        let (publisher, receiver) = match &parsed {
            LcmUrl::Memq => {
                let memq = Arc::new(Memq {
                    queue: Mutex::new(VecDeque::new()),
                    ready: Condvar::new(),
                });
                (Sender::Memq(Arc::clone(&memq)), Receiver::Memq(memq))
            }
            LcmUrl::Udpm(settings) => {
                let sender = udpm_sender(settings)?;
                let receiver = if settings.transmit_only {
                    Receiver::None
                } else {
                    udpm_receiver(settings)?
                };
                (sender, receiver)
            }
        };
        Ok(Self {
            url: parsed,
            publisher: Publisher {
                sender: Arc::new(publisher),
                auth: None,
            },
            receiver,
            subscriptions: Vec::new(),
            next_id: 0,
            unsubscribed: 0,
            verifier: None,
            own: OwnSenders::default(),
        })
    }

    /// Signs what this instance publishes on the channels `policy` covers
    /// and refuses (counts, never delivers) what it receives there without
    /// a valid, fresh tag (see [`crate::auth`]). Call it before handing out
    /// publishers: those taken earlier do not sign.
    #[must_use]
    pub fn authenticate(mut self, policy: AuthPolicy) -> Self {
        self.publisher.auth = Some(Arc::new((policy.clone(), Mutex::new(policy.signer()))));
        let verifier = policy.verifier();
        self.verifier = Some((policy, verifier));
        self
    }

    /// What authentication accepted and refused, per channel (`None` when
    /// it is off).
    pub fn auth_stats(&self) -> Option<&AuthStats> {
        self.verifier.as_ref().map(|(_, v)| v.stats())
    }

    /// Whether messages on `channel` are signed and verified (false when
    /// authentication is off).
    pub fn authenticates(&self, channel: &str) -> bool {
        self.verifier
            .as_ref()
            .is_some_and(|(policy, _)| policy.covers(channel))
    }

    /// Never delivers what `publisher` (of this process, on any bus) sends:
    /// a bridge forwarding onto a bus it also hears, however the two URLs
    /// are spelt, must not follow its own forwards. Dropped datagrams are
    /// counted in [`TransportStats::own`].
    pub fn ignore_from(&mut self, publisher: &Publisher) {
        self.own.ports.extend(publisher.source_port());
    }

    pub fn url(&self) -> &LcmUrl {
        &self.url
    }

    /// A publisher sharing this instance's socket, for other threads.
    pub fn publisher(&self) -> Publisher {
        self.publisher.clone()
    }

    /// Publishes raw bytes on `channel`.
    pub fn publish(&self, channel: &str, data: &[u8]) -> Result<(), TransportError> {
        self.publisher.publish(channel, data)
    }

    /// Encodes `message` and publishes it on `channel`.
    pub fn publish_message<M: Message>(
        &self,
        channel: &str,
        message: &M,
    ) -> Result<(), TransportError> {
        self.publisher.publish_message(channel, message)
    }

    /// Receives messages on exactly `channel`.
    pub fn subscribe(&mut self, channel: &str) -> SubscriptionId {
        self.add(ChannelFilter::Exact(channel.to_owned()))
    }

    /// Receives messages on every channel matching `pattern` as a whole
    /// (`ARC_VOTES_.*`), like the reference's `subscribe`.
    pub fn subscribe_regex(&mut self, pattern: &str) -> Result<SubscriptionId, TransportError> {
        let filter = ChannelFilter::pattern(pattern).map_err(|e| TransportError::BadPattern {
            pattern: pattern.to_owned(),
            reason: e.to_string(),
        })?;
        Ok(self.add(filter))
    }

    fn add(&mut self, filter: ChannelFilter) -> SubscriptionId {
        let id = SubscriptionId(self.next_id);
        self.next_id += 1;
        self.subscriptions.push((id, filter));
        id
    }

    /// Stops a subscription; returns whether it existed.
    pub fn unsubscribe(&mut self, id: SubscriptionId) -> bool {
        let before = self.subscriptions.len();
        self.subscriptions.retain(|(i, _)| *i != id);
        before != self.subscriptions.len()
    }

    fn wanted(&self, channel: &str) -> bool {
        self.subscriptions.iter().any(|(_, f)| f.matches(channel))
    }

    /// The next message on a subscribed channel, waiting at most `timeout`;
    /// `None` when none came in time.
    pub fn recv_timeout(
        &mut self,
        timeout: Duration,
    ) -> Result<Option<ReceivedMessage>, TransportError> {
        let deadline = Instant::now() + timeout;
        loop {
            let Some((channel, mut data)) = self.recv_any(deadline)? else {
                return Ok(None);
            };
            if !self.wanted(&channel) {
                self.unsubscribed += 1;
                continue;
            }
            let recv_utime = wall_clock_utime();
            if let Some((policy, verifier)) = &mut self.verifier
                && policy.covers(&channel)
            {
                let now = u64::try_from(recv_utime).unwrap_or(0);
                match verifier.verify(&channel, &data, now).map(<[u8]>::len) {
                    Ok(len) => data.truncate(len),
                    Err(refusal) => {
                        log_refusal(&channel, refusal, verifier.stats());
                        continue;
                    }
                }
            }
            return Ok(Some(ReceivedMessage {
                channel,
                data,
                recv_utime,
            }));
        }
    }

    fn recv_any(&mut self, deadline: Instant) -> Result<Option<(String, Vec<u8>)>, TransportError> {
        let own = &mut self.own;
        match &mut self.receiver {
            Receiver::None => {
                std::thread::sleep(deadline.saturating_duration_since(Instant::now()));
                Ok(None)
            }
            Receiver::Memq(memq) => {
                let mut queue = memq.queue.lock().unwrap_or_else(|e| e.into_inner());
                loop {
                    if let Some(message) = queue.pop_front() {
                        return Ok(Some(message));
                    }
                    let left = deadline.saturating_duration_since(Instant::now());
                    if left.is_zero() {
                        return Ok(None);
                    }
                    queue = memq
                        .ready
                        .wait_timeout(queue, left)
                        .unwrap_or_else(|e| e.into_inner())
                        .0;
                }
            }
            Receiver::Udpm {
                socket,
                buffer,
                reassembler,
            } => loop {
                let left = deadline.saturating_duration_since(Instant::now());
                // A zero read timeout means "block forever": poll instead.
                let wait = left.max(Duration::from_micros(1));
                socket
                    .set_read_timeout(Some(wait))
                    .map_err(io_error("cannot set the receive timeout"))?;
                match socket.recv_from(buffer) {
                    Ok((_, from)) if own.sent(from) => own.dropped += 1,
                    Ok((len, from)) => {
                        if let Some(message) =
                            reassembler.on_datagram(from, &buffer[..len], Instant::now())
                        {
                            return Ok(Some(message));
                        }
                    }
                    Err(e)
                        if matches!(
                            e.kind(),
                            io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut
                        ) =>
                    {
                        reassembler.expire(Instant::now());
                        if Instant::now() >= deadline {
                            return Ok(None);
                        }
                    }
                    Err(e) if e.kind() == io::ErrorKind::Interrupted => {}
                    Err(e) => return Err(io_error("cannot receive")(e)),
                }
            },
        }
    }

    /// Counters of the receiving side.
    pub fn stats(&self) -> TransportStats {
        TransportStats {
            reassembly: match &self.receiver {
                Receiver::Udpm { reassembler, .. } => reassembler.stats(),
                _ => ReassemblyStats::default(),
            },
            unsubscribed: self.unsubscribed,
            own: self.own.dropped,
        }
    }
}

/// Warns of the first refusal of each reason on a channel and of every
/// thousandth after it; all are counted in [`AuthStats`].
fn log_refusal(channel: &str, refusal: Refusal, stats: &AuthStats) {
    let count = stats
        .channels
        .get(channel)
        .map_or(0, |counts| counts.refused[refusal.index()]);
    if count % 1000 == 1 {
        tracing::warn!(
            channel,
            %refusal,
            count,
            "message refused: authentication is on for this channel"
        );
    }
}

/// What the receiving side has seen.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TransportStats {
    pub reassembly: ReassemblyStats,
    /// Complete messages on channels nobody subscribed to.
    pub unsubscribed: u64,
    /// Datagrams this process sent itself, not heard ([`Lcm::ignore_from`]).
    pub own: u64,
}

fn udpm_sender(settings: &UdpmUrl) -> Result<Sender, TransportError> {
    let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
        .map_err(io_error("cannot create a UDP socket"))?;
    socket
        .set_multicast_ttl_v4(u32::from(settings.ttl))
        .map_err(io_error("cannot set the multicast TTL"))?;
    socket
        .set_multicast_loop_v4(true)
        .map_err(io_error("cannot enable multicast loopback"))?;
    socket
        .bind(&SocketAddr::from((Ipv4Addr::UNSPECIFIED, 0)).into())
        .map_err(io_error("cannot bind the sending socket"))?;
    Ok(Sender::Udpm {
        socket: socket.into(),
        destination: SocketAddrV4::new(settings.group, settings.port),
        seqno: AtomicU32::new(0),
    })
}

fn udpm_receiver(settings: &UdpmUrl) -> Result<Receiver, TransportError> {
    let socket = Socket::new(Domain::IPV4, Type::DGRAM, Some(Protocol::UDP))
        .map_err(io_error("cannot create a UDP socket"))?;
    socket
        .set_reuse_address(true)
        .map_err(io_error("cannot set SO_REUSEADDR"))?;
    #[cfg(unix)]
    socket
        .set_reuse_port(true)
        .map_err(io_error("cannot set SO_REUSEPORT"))?;
    let requested = settings.recv_buf_size.unwrap_or(DEFAULT_RECV_BUF_SIZE);
    socket
        .set_recv_buffer_size(requested)
        .map_err(io_error("cannot set the receive buffer size"))?;
    if socket
        .recv_buffer_size()
        .is_ok_and(|granted| granted < requested)
    {
        // Privileged processes may exceed net.core.rmem_max.
        force_recv_buffer_size(&socket, requested);
    }
    if let Ok(granted) = socket.recv_buffer_size()
        && granted < requested.min(2 << 20)
    {
        tracing::warn!(
            requested,
            granted,
            "small LCM receive buffer: large messages may be dropped (raise net.core.rmem_max)"
        );
    }
    socket
        .bind(&SocketAddr::from((Ipv4Addr::UNSPECIFIED, settings.port)).into())
        .map_err(io_error(format!("cannot bind UDP port {}", settings.port)))?;
    socket
        .join_multicast_v4(&settings.group, &Ipv4Addr::UNSPECIFIED)
        .map_err(io_error(format!(
            "cannot join multicast group {} (is there a multicast route? e.g. `ip route add 224.0.0.0/4 dev lo`)",
            settings.group
        )))?;
    Ok(Receiver::Udpm {
        socket: socket.into(),
        buffer: vec![0; 65_536],
        reassembler: Reassembler::default(),
    })
}

#[cfg(target_os = "linux")]
fn force_recv_buffer_size(socket: &Socket, bytes: usize) {
    use std::os::fd::AsRawFd;
    let value = libc::c_int::try_from(bytes).unwrap_or(libc::c_int::MAX);
    // SAFETY: a setsockopt on a valid socket with a correctly sized int; a
    // failure (no CAP_NET_ADMIN) leaves the buffer as it was.
    unsafe {
        libc::setsockopt(
            socket.as_raw_fd(),
            libc::SOL_SOCKET,
            libc::SO_RCVBUFFORCE,
            (&raw const value).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        );
    }
}

#[cfg(not(target_os = "linux"))]
fn force_recv_buffer_size(_socket: &Socket, _bytes: usize) {}

/// Wall-clock time in µs since the Unix epoch (transport timestamps only;
/// the navigation nodes never read a clock).
pub fn wall_clock_utime() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_micros()).unwrap_or(i64::MAX))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_bus_spelt_two_ways_is_one_bus() {
        let parse = |u: &str| u.parse::<LcmUrl>().unwrap();
        let default = parse("udpm://239.255.76.67:7667?ttl=0");
        for same in [
            "udpm://",
            "",
            "udpm://239.255.76.67:7667",
            "udpm://239.255.76.67:7667?ttl=1&recv_buf_size=65536",
        ] {
            assert!(parse(same).same_bus(&default), "{same}");
        }
        for other in [
            "udpm://239.255.76.68:7667",
            "udpm://239.255.76.67:7668",
            "memq://",
        ] {
            assert!(!parse(other).same_bus(&default), "{other}");
        }
        assert!(!parse("memq://").same_bus(&parse("memq://")));
    }

    /// Inside a network namespace of its own: a bridge forwarding onto the
    /// bus it hears (here through a second URL for it) hears none of its
    /// forwards, counts them, and still hears everyone else.
    #[test]
    fn what_a_process_forwards_onto_the_bus_it_hears_is_not_heard() {
        let Some(ns) = arcnav_testkit::NetNs::require("own-forwards") else {
            return;
        };
        ns.run(|| {
            let mut heard = Lcm::new("udpm://239.255.76.67:7667?ttl=0").unwrap();
            heard.subscribe("STEERING_COMMAND");
            let forward = Lcm::new("udpm://").unwrap().publisher();
            heard.ignore_from(&forward);
            let other = Lcm::new("udpm://239.255.76.67:7667").unwrap();
            for _ in 0..3 {
                forward.publish("STEERING_COMMAND", b"own").unwrap();
            }
            other.publish("STEERING_COMMAND", b"theirs").unwrap();
            let wait = Duration::from_millis(300);
            let got: Vec<Vec<u8>> = std::iter::from_fn(|| heard.recv_timeout(wait).unwrap())
                .map(|m| m.data)
                .collect();
            assert_eq!(got, [b"theirs".to_vec()]);
            assert_eq!(heard.stats().own, 3);
        });
    }

    #[test]
    fn memq_delivers_to_matching_subscriptions_only() {
        let mut lcm = Lcm::new("memq://").unwrap();
        lcm.subscribe("POSE");
        let votes = lcm.subscribe_regex("ARC_VOTES_.*").unwrap();
        lcm.publish("POSE", b"p").unwrap();
        lcm.publish("OTHER", b"o").unwrap();
        lcm.publish("ARC_VOTES_GOAL", b"v").unwrap();
        lcm.publish("XARC_VOTES_GOAL", b"anchored").unwrap();
        let short = Duration::from_millis(10);
        let got: Vec<String> = std::iter::from_fn(|| lcm.recv_timeout(short).unwrap())
            .map(|m| m.channel)
            .collect();
        assert_eq!(got, ["POSE", "ARC_VOTES_GOAL"]);
        assert_eq!(lcm.stats().unsubscribed, 2);
        assert!(lcm.unsubscribe(votes));
        lcm.publish("ARC_VOTES_GOAL", b"v").unwrap();
        assert!(lcm.recv_timeout(short).unwrap().is_none());
    }

    #[test]
    fn a_publisher_from_another_thread_wakes_the_receiver() {
        let mut lcm = Lcm::new("memq://").unwrap();
        lcm.subscribe("X");
        let publisher = lcm.publisher();
        let t = std::thread::spawn(move || {
            std::thread::sleep(Duration::from_millis(20));
            publisher.publish("X", b"hello").unwrap();
        });
        let m = lcm.recv_timeout(Duration::from_secs(5)).unwrap().unwrap();
        assert_eq!(m.data, b"hello");
        t.join().unwrap();
    }

    #[test]
    fn bad_channels_and_patterns_are_refused() {
        let lcm = Lcm::new("memq://").unwrap();
        assert!(matches!(
            lcm.publish("", b""),
            Err(TransportError::BadChannel { .. })
        ));
        assert!(matches!(
            lcm.publish(&"C".repeat(64), b""),
            Err(TransportError::BadChannel { .. })
        ));
        let mut lcm = lcm;
        assert!(matches!(
            lcm.subscribe_regex("("),
            Err(TransportError::BadPattern { .. })
        ));
        assert!(matches!(Lcm::new("tcp://x"), Err(TransportError::Url(_))));
    }
}
