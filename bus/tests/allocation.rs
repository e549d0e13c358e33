//! Input never makes the process allocate from a size it only claims: a
//! damaged log header or a datagram may say 256 MiB, the memory taken is
//! what actually came.

use std::net::{Ipv4Addr, SocketAddr};
use std::sync::Mutex;
use std::time::Instant;

use arcnav_bus::log::{LogReader, LogWriter};
use arcnav_bus::transport::udpm::{MAX_MESSAGE_SIZE, Reassembler};
use arcnav_testkit::alloc::Largest;

#[global_allocator]
static ALLOC: Largest = Largest::new();

/// One measurement at a time (tests run on threads of one process).
static SERIAL: Mutex<()> = Mutex::new(());

#[test]
fn a_log_event_header_claiming_256_mib_costs_only_the_bytes_there() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    let mut writer = LogWriter::new(Vec::new());
    writer.write_event(1, "POSE", &[1, 2, 3]).unwrap();
    let mut bytes = writer.into_inner();
    // The data length field of the only event: 2^28 bytes.
    bytes[24..28].copy_from_slice(&(1i32 << 28).to_be_bytes());
    ALLOC.reset();
    let events: Vec<_> = LogReader::new(&bytes[..]).collect();
    assert!(events.iter().all(Result::is_ok));
    assert!(
        ALLOC.largest() < 1 << 20,
        "allocated {} bytes",
        ALLOC.largest()
    );
}

#[test]
fn a_datagram_claiming_a_256_mib_message_costs_only_its_own_bytes() {
    let _serial = SERIAL.lock().unwrap_or_else(|e| e.into_inner());
    // LC03, one fragment of one, 10 bytes, msg_size 2^28.
    let mut packet = Vec::new();
    packet.extend_from_slice(&0x4c43_3033u32.to_be_bytes());
    packet.extend_from_slice(&7u32.to_be_bytes());
    packet.extend_from_slice(&(MAX_MESSAGE_SIZE as u32).to_be_bytes());
    packet.extend_from_slice(&0u32.to_be_bytes());
    packet.extend_from_slice(&0u16.to_be_bytes());
    packet.extend_from_slice(&1u16.to_be_bytes());
    packet.extend_from_slice(b"X\0tenbytes!");
    let mut reassembler = Reassembler::default();
    ALLOC.reset();
    let from = SocketAddr::from((Ipv4Addr::LOCALHOST, 7667));
    assert!(
        reassembler
            .on_datagram(from, &packet, Instant::now())
            .is_none()
    );
    assert!(
        ALLOC.largest() < 1 << 20,
        "allocated {} bytes",
        ALLOC.largest()
    );
}
