//! Random values round-trip; malformed messages and logs never panic.

mod common;

use arcnav_bus::lcmtypes::*;
use arcnav_bus::{AnyMessage, DecodeError, EncodeError, LogReader, LogWriter, Message};
use common::{Rng, random_message, samples};
use proptest::prelude::*;

fn bits_equal(a: &AnyMessage, b: &AnyMessage) -> bool {
    // Encodings compare NaNs bit for bit, where PartialEq would not.
    a.encode().unwrap() == b.encode().unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn random_values_of_every_type_round_trip(seed: u64, kind in 0usize..9) {
        let (_, message) = random_message(&mut Rng::new(seed), kind);
        let bytes = message.encode().unwrap();
        let back = AnyMessage::decode(&bytes).unwrap().expect("a known type");
        prop_assert!(bits_equal(&message, &back));
    }

    #[test]
    fn arbitrary_bytes_never_panic_the_decoder(bytes in proptest::collection::vec(any::<u8>(), 0..256)) {
        let _ = AnyMessage::decode(&bytes);
        for (_, sample) in samples() {
            // Behind a valid fingerprint, so decoding goes past the header.
            let mut framed = sample.encode().unwrap()[..8].to_vec();
            framed.extend_from_slice(&bytes);
            let _ = AnyMessage::decode(&framed);
        }
    }

    #[test]
    fn flipped_bits_never_panic_the_decoder(seed: u64, kind in 0usize..9, flips in 1usize..8) {
        let mut rng = Rng::new(seed);
        let (_, message) = random_message(&mut rng, kind);
        let mut bytes = message.encode().unwrap();
        for _ in 0..flips {
            let i = rng.below(bytes.len());
            bytes[i] ^= 1 << rng.below(8);
        }
        let _ = AnyMessage::decode(&bytes);
    }

    #[test]
    fn mutated_logs_never_panic_and_always_end(seed: u64, cuts in 0usize..4, flips in 0usize..32) {
        let mut rng = Rng::new(seed);
        let mut writer = LogWriter::new(Vec::new());
        for i in 0..10 {
            let (_, message) = random_message(&mut rng, i);
            writer.write_event(i as i64, "CHANNEL", &message.encode().unwrap()).unwrap();
        }
        let mut log = writer.into_inner();
        for _ in 0..flips {
            let i = rng.below(log.len());
            log[i] ^= 1 << rng.below(8);
        }
        for _ in 0..cuts {
            let at = rng.below(log.len());
            let len = rng.below(64).min(log.len() - at);
            log.drain(at..at + len);
        }
        let total = log.len() as u64;
        let mut reader = LogReader::new(log.as_slice());
        let mut data_bytes = 0u64;
        for event in reader.by_ref() {
            let event = event.unwrap();
            data_bytes += (28 + event.channel.len() + event.data.len()) as u64;
            let _ = AnyMessage::decode(&event.data);
        }
        let stats = reader.stats();
        // Every byte is accounted for: read as an event, skipped, or a truncated tail.
        prop_assert_eq!(data_bytes + stats.skipped_bytes + stats.truncated_tail_bytes, total);
    }
}

#[test]
fn every_truncation_of_every_sample_is_a_typed_error() {
    for (name, sample) in samples() {
        let bytes = sample.encode().unwrap();
        for len in 0..bytes.len() {
            match AnyMessage::decode(&bytes[..len]) {
                Err(_) => {}
                Ok(None) if len < 8 => {}
                other => panic!("{name} cut to {len} bytes decoded as {other:?}"),
            }
        }
    }
}

#[test]
fn trailing_bytes_are_refused() {
    let mut bytes = pose_t::default().encode().unwrap();
    bytes.push(0);
    assert_eq!(
        pose_t::decode(&bytes),
        Err(DecodeError::TrailingBytes { count: 1 })
    );
}

#[test]
fn a_wrong_fingerprint_is_named() {
    let bytes = pose_t::default().encode().unwrap();
    let err = steering_command_t::decode(&bytes).unwrap_err();
    assert!(matches!(
        err,
        DecodeError::Fingerprint {
            type_name: "arcnav.steering_command_t",
            ..
        }
    ));
    assert!(
        err.to_string()
            .contains("is not that of arcnav.steering_command_t"),
        "{err}"
    );
}

#[test]
fn negative_and_absurd_sizes_are_refused_without_allocating() {
    let image = common::range_image(4, 8, "erim");
    let bytes = image.encode().unwrap();
    // rows sits after utime(8) + sensor(4+4+1) + mount (7*8) behind the fingerprint.
    let rows_at = 8 + 8 + 9 + 56;
    assert_eq!(&bytes[rows_at..rows_at + 4], &4i32.to_be_bytes());
    let mut negative = bytes.clone();
    negative[rows_at..rows_at + 4].copy_from_slice(&(-1i32).to_be_bytes());
    assert_eq!(
        range_image_t::decode(&negative),
        Err(DecodeError::NegativeSize {
            field: "rows",
            value: -1
        })
    );
    let mut huge = bytes.clone();
    huge[rows_at..rows_at + 4].copy_from_slice(&i32::MAX.to_be_bytes());
    assert!(matches!(
        range_image_t::decode(&huge),
        Err(DecodeError::SizeTooLarge {
            field: "elevation",
            ..
        })
    ));
    // cols * rows overflowing what is left (each fits alone).
    let mut product = bytes.clone();
    product[rows_at..rows_at + 4].copy_from_slice(&4i32.to_be_bytes());
    product[rows_at + 4..rows_at + 8].copy_from_slice(&(1i32 << 30).to_be_bytes());
    assert!(range_image_t::decode(&product).is_err());
}

#[test]
fn invalid_utf8_is_refused() {
    let message = arc_votes_t {
        behaviour: "ab".into(),
        ..Default::default()
    };
    let mut bytes = message.encode().unwrap();
    // behaviour: length at 16..20, bytes at 20..22.
    bytes[20] = 0xff;
    assert_eq!(
        arc_votes_t::decode(&bytes),
        Err(DecodeError::InvalidUtf8 { field: "behaviour" })
    );
}

#[test]
fn encoding_refuses_sizes_that_disagree_with_the_data() {
    let mut image = common::range_image(4, 8, "erim");
    image.range.pop();
    assert_eq!(
        image.encode(),
        Err(EncodeError::SizeMismatch {
            field: "range",
            declared: 32,
            actual: 31
        })
    );
    let votes = arc_votes_t {
        num_arcs: -2,
        ..Default::default()
    };
    assert_eq!(
        votes.encode(),
        Err(EncodeError::NegativeSize {
            field: "num_arcs",
            value: -2
        })
    );
    let cells = obstacle_cells_t {
        num_cells: 1,
        cells: vec![obstacle_cell_t::default()],
        num_fov: 1,
        fov: vec![],
        ..Default::default()
    };
    assert!(matches!(
        cells.encode(),
        Err(EncodeError::SizeMismatch { field: "fov", .. })
    ));
}
