//! LCM binary encoding: big-endian numbers, `boolean` as one byte,
//! `string` as an `int32` length counting a trailing NUL, arrays without a
//! length prefix (their size is an earlier member), multi-dimensional arrays
//! row-major. A top-level message starts with its 8-byte fingerprint.
//!
//! Decoding never panics and is bounded: every size is checked against the
//! bytes actually left before anything is allocated, so a forged length can
//! not make the decoder allocate more than the input justifies.

/// A message that cannot be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("message ends early: `{field}` needs {needed} bytes, {available} left")]
    Truncated {
        field: &'static str,
        needed: usize,
        available: usize,
    },
    #[error("fingerprint {found:#018x} is not that of {type_name} ({expected:#018x})")]
    Fingerprint {
        type_name: &'static str,
        expected: u64,
        found: u64,
    },
    #[error("size `{field}` is {value}: an array size must not be negative")]
    NegativeSize { field: &'static str, value: i64 },
    #[error("`{field}` declares {count} elements, more than the {available} bytes left can hold")]
    SizeTooLarge {
        field: &'static str,
        count: u64,
        available: usize,
    },
    #[error("string `{field}` has length {length}: it must count at least its NUL terminator")]
    BadStringLength { field: &'static str, length: i64 },
    #[error("string `{field}` is not NUL-terminated")]
    MissingNul { field: &'static str },
    #[error("string `{field}` is not valid UTF-8")]
    InvalidUtf8 { field: &'static str },
    #[error("{count} unexpected bytes after the end of the message")]
    TrailingBytes { count: usize },
}

/// A message that cannot be encoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    #[error("`{field}` holds {actual} elements but its size members say {declared}")]
    SizeMismatch {
        field: &'static str,
        declared: u64,
        actual: usize,
    },
    #[error("size `{field}` is {value}: an array size must not be negative")]
    NegativeSize { field: &'static str, value: i64 },
    #[error("string `{field}` contains a NUL byte, which LCM strings cannot carry")]
    NulInString { field: &'static str },
    #[error("`{field}` is too long for LCM ({len} bytes)")]
    TooLong { field: &'static str, len: usize },
}

/// A cursor over the bytes of one message.
#[derive(Debug, Clone)]
pub struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    pub fn new(data: &'a [u8]) -> Self {
        Self { data, pos: 0 }
    }

    /// Bytes not yet read.
    pub fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    /// The next `n` bytes, or `Truncated`.
    pub fn take(&mut self, n: usize, field: &'static str) -> Result<&'a [u8], DecodeError> {
        let available = self.remaining();
        if n > available {
            return Err(DecodeError::Truncated {
                field,
                needed: n,
                available,
            });
        }
        let bytes = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(bytes)
    }

    fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], DecodeError> {
        let bytes = self.take(N, field)?;
        let mut out = [0u8; N];
        out.copy_from_slice(bytes);
        Ok(out)
    }

    /// Checks that `count` elements of at least `min_size` bytes each can fit
    /// in what is left; the caller may then allocate for them.
    pub fn check_count(
        &self,
        count: usize,
        min_size: usize,
        field: &'static str,
    ) -> Result<(), DecodeError> {
        let available = self.remaining();
        match count.checked_mul(min_size) {
            Some(bytes) if bytes <= available => Ok(()),
            _ => Err(DecodeError::SizeTooLarge {
                field,
                count: count as u64,
                available,
            }),
        }
    }

    /// Fails unless every byte was read.
    pub fn finish(&self) -> Result<(), DecodeError> {
        match self.remaining() {
            0 => Ok(()),
            count => Err(DecodeError::TrailingBytes { count }),
        }
    }
}

/// Turns a decoded size member into a count.
pub fn decoded_size(field: &'static str, value: i64) -> Result<usize, DecodeError> {
    usize::try_from(value).map_err(|_| DecodeError::NegativeSize { field, value })
}

/// Turns a size member into a count when encoding.
pub fn encoded_size(field: &'static str, value: i64) -> Result<usize, EncodeError> {
    usize::try_from(value).map_err(|_| EncodeError::NegativeSize { field, value })
}

/// Product of array dimensions, saturating (a saturated product never matches
/// a real length, and never fits in the input).
pub fn product(sizes: &[usize]) -> usize {
    sizes
        .iter()
        .try_fold(1usize, |acc, &n| acc.checked_mul(n))
        .unwrap_or(usize::MAX)
}

/// Checks that a variable-size array holds exactly `declared` elements.
pub fn check_len(field: &'static str, declared: usize, actual: usize) -> Result<(), EncodeError> {
    if declared == actual {
        Ok(())
    } else {
        Err(EncodeError::SizeMismatch {
            field,
            declared: declared as u64,
            actual,
        })
    }
}

/// A value with an LCM encoding (primitives, fixed arrays, generated structs).
pub trait Wire: Sized {
    /// Fewest bytes one value can take on the wire.
    const MIN_SIZE: usize;

    /// Appends the encoding to `out` (no fingerprint).
    fn write(&self, out: &mut Vec<u8>);

    /// Reads one value.
    fn read(r: &mut Reader<'_>, field: &'static str) -> Result<Self, DecodeError>;

    /// Bytes `write` appends.
    fn encoded_len(&self) -> usize;

    /// Checks what `write` cannot express (array sizes, strings).
    fn check(&self, _field: &'static str) -> Result<(), EncodeError> {
        Ok(())
    }

    /// Appends a slice; numbers override this with a bulk conversion.
    fn write_slice(values: &[Self], out: &mut Vec<u8>) {
        for v in values {
            v.write(out);
        }
    }

    /// Reads `count` values, allocating no more than the input can hold.
    fn read_vec(
        r: &mut Reader<'_>,
        count: usize,
        field: &'static str,
    ) -> Result<Vec<Self>, DecodeError> {
        r.check_count(count, Self::MIN_SIZE.max(1), field)?;
        let mut out = Vec::with_capacity(count);
        for _ in 0..count {
            out.push(Self::read(r, field)?);
        }
        Ok(out)
    }

    fn slice_len(values: &[Self]) -> usize {
        values.iter().map(Self::encoded_len).sum()
    }

    fn check_slice(values: &[Self], field: &'static str) -> Result<(), EncodeError> {
        values.iter().try_for_each(|v| v.check(field))
    }
}

macro_rules! wire_number {
    ($t:ty, $bits:ty, $size:expr, $to:expr, $from:expr) => {
        impl Wire for $t {
            const MIN_SIZE: usize = $size;

            fn write(&self, out: &mut Vec<u8>) {
                out.extend_from_slice(&($to)(*self).to_be_bytes());
            }

            fn read(r: &mut Reader<'_>, field: &'static str) -> Result<Self, DecodeError> {
                Ok(($from)(<$bits>::from_be_bytes(r.array::<$size>(field)?)))
            }

            fn encoded_len(&self) -> usize {
                $size
            }

            fn write_slice(values: &[Self], out: &mut Vec<u8>) {
                let start = out.len();
                out.resize(start + values.len() * $size, 0);
                for (dst, v) in out[start..].chunks_exact_mut($size).zip(values) {
                    dst.copy_from_slice(&($to)(*v).to_be_bytes());
                }
            }

            fn read_vec(
                r: &mut Reader<'_>,
                count: usize,
                field: &'static str,
            ) -> Result<Vec<Self>, DecodeError> {
                r.check_count(count, $size, field)?;
                let bytes = r.take(count * $size, field)?;
                Ok(bytes
                    .chunks_exact($size)
                    .map(|c| {
                        let mut b = [0u8; $size];
                        b.copy_from_slice(c);
                        ($from)(<$bits>::from_be_bytes(b))
                    })
                    .collect())
            }

            fn slice_len(values: &[Self]) -> usize {
                values.len() * $size
            }
        }
    };
}

wire_number!(i8, i8, 1, |v: i8| v, |v: i8| v);
wire_number!(u8, u8, 1, |v: u8| v, |v: u8| v);
wire_number!(i16, i16, 2, |v: i16| v, |v: i16| v);
wire_number!(i32, i32, 4, |v: i32| v, |v: i32| v);
wire_number!(i64, i64, 8, |v: i64| v, |v: i64| v);
wire_number!(f32, u32, 4, f32::to_bits, f32::from_bits);
wire_number!(f64, u64, 8, f64::to_bits, f64::from_bits);
// LCM writes 0/1; like the reference decoders, any non-zero byte is true.
wire_number!(bool, u8, 1, u8::from, |b: u8| b != 0);

impl Wire for String {
    const MIN_SIZE: usize = 5;

    fn write(&self, out: &mut Vec<u8>) {
        // `check` guarantees the length fits.
        let len = i32::try_from(self.len() + 1).unwrap_or(i32::MAX);
        len.write(out);
        out.extend_from_slice(self.as_bytes());
        out.push(0);
    }

    fn read(r: &mut Reader<'_>, field: &'static str) -> Result<Self, DecodeError> {
        let length = i32::read(r, field)?;
        let len = usize::try_from(length).ok().filter(|&n| n >= 1).ok_or(
            DecodeError::BadStringLength {
                field,
                length: i64::from(length),
            },
        )?;
        let bytes = r.take(len, field)?;
        let (text, nul) = bytes.split_at(len - 1);
        if nul != [0] {
            return Err(DecodeError::MissingNul { field });
        }
        std::str::from_utf8(text)
            .map(str::to_owned)
            .map_err(|_| DecodeError::InvalidUtf8 { field })
    }

    fn encoded_len(&self) -> usize {
        4 + self.len() + 1
    }

    fn check(&self, field: &'static str) -> Result<(), EncodeError> {
        if self.as_bytes().contains(&0) {
            return Err(EncodeError::NulInString { field });
        }
        if self.len() >= i32::MAX as usize {
            return Err(EncodeError::TooLong {
                field,
                len: self.len(),
            });
        }
        Ok(())
    }
}

impl<T: Wire + Default, const N: usize> Wire for [T; N] {
    const MIN_SIZE: usize = N * T::MIN_SIZE;

    fn write(&self, out: &mut Vec<u8>) {
        T::write_slice(self, out);
    }

    fn read(r: &mut Reader<'_>, field: &'static str) -> Result<Self, DecodeError> {
        r.check_count(N, T::MIN_SIZE, field)?;
        let mut out: [T; N] = std::array::from_fn(|_| T::default());
        for slot in &mut out {
            *slot = T::read(r, field)?;
        }
        Ok(out)
    }

    fn encoded_len(&self) -> usize {
        T::slice_len(self)
    }

    fn check(&self, field: &'static str) -> Result<(), EncodeError> {
        T::check_slice(self, field)
    }
}

/// A top-level LCM type: fingerprint + encoding.
pub trait Message: Wire {
    /// `package.name` as in the `.lcm` file.
    const TYPE_NAME: &'static str;
    /// The fingerprint lcm-gen computes for the type.
    const FINGERPRINT: u64;

    /// Fingerprint and fields, ready to publish or log.
    fn encode(&self) -> Result<Vec<u8>, EncodeError> {
        let mut out = Vec::new();
        self.encode_into(&mut out)?;
        Ok(out)
    }

    /// Like [`Message::encode`], reusing `out` (cleared first).
    fn encode_into(&self, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        self.check(Self::TYPE_NAME)?;
        out.clear();
        out.reserve(8 + self.encoded_len());
        out.extend_from_slice(&Self::FINGERPRINT.to_be_bytes());
        self.write(out);
        Ok(())
    }

    /// Decodes a whole message: fingerprint, fields, nothing after.
    fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        let mut r = Reader::new(bytes);
        let found = u64::from_be_bytes(r.array::<8>("fingerprint")?);
        if found != Self::FINGERPRINT {
            return Err(DecodeError::Fingerprint {
                type_name: Self::TYPE_NAME,
                expected: Self::FINGERPRINT,
                found,
            });
        }
        let value = Self::read(&mut r, Self::TYPE_NAME)?;
        r.finish()?;
        Ok(value)
    }
}

/// The fingerprint at the start of an encoded message, if there is one.
pub fn peek_fingerprint(bytes: &[u8]) -> Option<u64> {
    let head: [u8; 8] = bytes.get(..8)?.try_into().ok()?;
    Some(u64::from_be_bytes(head))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_are_big_endian() {
        let mut out = Vec::new();
        1_700_000_000_000_000i64.write(&mut out);
        0.25f32.write(&mut out);
        (-1.5f32).write(&mut out);
        true.write(&mut out);
        assert_eq!(
            out,
            [
                0, 6, 10, 36, 24, 30, 64, 0, 0x3e, 0x80, 0, 0, 0xbf, 0xc0, 0, 0, 1
            ]
        );
    }

    #[test]
    fn strings_count_their_nul() {
        let mut out = Vec::new();
        "erim".to_owned().write(&mut out);
        assert_eq!(out, [0, 0, 0, 5, b'e', b'r', b'i', b'm', 0]);
        let mut r = Reader::new(&out);
        assert_eq!(String::read(&mut r, "s").unwrap(), "erim");
        r.finish().unwrap();
    }

    #[test]
    fn bad_strings_are_typed_errors() {
        let read = |bytes: &[u8]| String::read(&mut Reader::new(bytes), "s");
        assert_eq!(
            read(&[0, 0, 0, 0]),
            Err(DecodeError::BadStringLength {
                field: "s",
                length: 0
            })
        );
        assert_eq!(
            read(&[0xff, 0xff, 0xff, 0xff]),
            Err(DecodeError::BadStringLength {
                field: "s",
                length: -1
            })
        );
        assert_eq!(
            read(&[0, 0, 0, 2, b'a', b'b']),
            Err(DecodeError::MissingNul { field: "s" })
        );
        assert_eq!(
            read(&[0, 0, 0, 2, 0xff, 0]),
            Err(DecodeError::InvalidUtf8 { field: "s" })
        );
        assert!(matches!(
            read(&[0x7f, 0, 0, 0, b'a']),
            Err(DecodeError::Truncated { .. })
        ));
        assert_eq!(
            "a\0b".to_owned().check("s"),
            Err(EncodeError::NulInString { field: "s" })
        );
    }

    #[test]
    fn a_huge_declared_count_is_refused_before_allocating() {
        let bytes = [0u8; 16];
        let mut r = Reader::new(&bytes);
        assert_eq!(
            f32::read_vec(&mut r, 1 << 40, "range"),
            Err(DecodeError::SizeTooLarge {
                field: "range",
                count: 1 << 40,
                available: 16
            })
        );
        assert!(
            String::read_vec(&mut r, 4, "names").is_err(),
            "4 strings need 20 bytes"
        );
        assert_eq!(
            decoded_size("n", -3),
            Err(DecodeError::NegativeSize {
                field: "n",
                value: -3
            })
        );
        assert_eq!(product(&[usize::MAX, 2]), usize::MAX);
    }

    #[test]
    fn bulk_float_arrays_round_trip_bit_for_bit() {
        let values = [
            0.0f32,
            -0.0,
            1.5,
            f32::NAN,
            f32::INFINITY,
            f32::MIN_POSITIVE,
            -7.25,
        ];
        let mut out = Vec::new();
        f32::write_slice(&values, &mut out);
        assert_eq!(&out[8..12], &1.5f32.to_be_bytes());
        let back = f32::read_vec(&mut Reader::new(&out), values.len(), "v").unwrap();
        let bits = |v: &[f32]| v.iter().map(|f| f.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back), bits(&values));
    }

    #[test]
    fn fixed_arrays_nest_row_major() {
        let pose = [[1.0f64, 2.0], [3.0, 4.0]];
        let mut out = Vec::new();
        pose.write(&mut out);
        assert_eq!(&out[16..24], &3.0f64.to_be_bytes());
        assert_eq!(
            <[[f64; 2]; 2]>::read(&mut Reader::new(&out), "pose").unwrap(),
            pose
        );
    }
}
