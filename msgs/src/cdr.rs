//! Strict CDR decoding (OMG CDR as ROS 2 puts it on the wire: XCDR1, 4-byte length prefixes,
//! natural alignment counted from the start of the payload). A message either decodes exactly,
//! every byte accounted for, or it is refused whole with the reason:
//!
//! - a value that runs past the end (a message missing its last byte);
//! - bytes after the end, beyond the zero padding that rounds a payload up to 4 bytes;
//! - a string whose length is 0 (CDR counts the terminating NUL, so the shortest string has
//!   length 1), that does not end with NUL, that holds a NUL inside, or that is not UTF-8;
//! - a boolean other than 0 or 1;
//! - a sequence that claims more elements than there are bytes left.
//!
//! Alignment padding is skipped whatever it holds: CDR leaves its content undefined, and Fast
//! DDS (rclpy's default middleware) does not zero it. Every accepted payload therefore
//! re-encodes to its own bytes except in its padding, which [`decode_with_padding`] reports.
//!
//! Lenient decoders accept such input and shift every later field (issue 10, finding 3).

use serde::de::{self, DeserializeSeed, SeqAccess, Visitor};
use serde::Deserialize;

/// The byte order of a payload: its encapsulation header says which (`CDR_LE`, `CDR_BE`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    Little,
    Big,
}

/// Why a payload was refused; `at` is the byte offset in the payload.
#[derive(Debug, Clone, PartialEq)]
pub enum CdrError {
    Truncated {
        at: usize,
        needed: usize,
    },
    Trailing {
        at: usize,
        count: usize,
    },
    EmptyString {
        at: usize,
    },
    Unterminated {
        at: usize,
    },
    InnerNul {
        at: usize,
    },
    NotUtf8 {
        at: usize,
    },
    BadBool {
        at: usize,
        value: u8,
    },
    TooLong {
        at: usize,
        count: usize,
        left: usize,
    },
    Unsupported(&'static str),
    Custom(String),
}

impl std::fmt::Display for CdrError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CdrError::Truncated { at, needed } => {
                write!(
                    f,
                    "the message ends early: {needed} more bytes needed at byte {at}"
                )
            }
            CdrError::Trailing { at, count } => {
                write!(
                    f,
                    "{count} unexpected bytes after the message's end at byte {at}"
                )
            }
            CdrError::EmptyString { at } => write!(
                f,
                "string at byte {at} has length 0 (a CDR string counts its terminating NUL)"
            ),
            CdrError::Unterminated { at } => {
                write!(f, "string at byte {at} does not end with NUL")
            }
            CdrError::InnerNul { at } => write!(f, "string at byte {at} holds a NUL"),
            CdrError::NotUtf8 { at } => write!(f, "string at byte {at} is not UTF-8"),
            CdrError::BadBool { at, value } => {
                write!(f, "boolean at byte {at} is {value}, not 0 or 1")
            }
            CdrError::TooLong { at, count, left } => write!(
                f,
                "sequence at byte {at} claims {count} elements with {left} bytes left"
            ),
            CdrError::Unsupported(what) => write!(f, "CDR cannot carry {what}"),
            CdrError::Custom(msg) => f.write_str(msg),
        }
    }
}

impl std::error::Error for CdrError {}

impl de::Error for CdrError {
    fn custom<T: std::fmt::Display>(msg: T) -> Self {
        CdrError::Custom(msg.to_string())
    }
}

/// Decodes a whole payload (the bytes after the 4-byte encapsulation header) as `T`.
pub fn from_bytes<'de, T: Deserialize<'de>>(
    payload: &'de [u8],
    order: ByteOrder,
) -> Result<T, CdrError> {
    decode_with_padding(payload, order).map(|(value, _)| value)
}

/// [`from_bytes`], and the byte ranges that were padding (alignment, and the end rounded up
/// to a multiple of 4).
pub fn decode_with_padding<'de, T: Deserialize<'de>>(
    payload: &'de [u8],
    order: ByteOrder,
) -> Result<(T, Vec<std::ops::Range<usize>>), CdrError> {
    let mut decoder = Decoder {
        input: payload,
        pos: 0,
        order,
        padding: Vec::new(),
    };
    let value = T::deserialize(&mut decoder)?;
    let rest = payload.len() - decoder.pos;
    // Writers may round the payload up to a multiple of 4; nothing else may follow.
    if rest > 0 && !(rest < 4 && payload.len().is_multiple_of(4)) {
        return Err(CdrError::Trailing {
            at: decoder.pos,
            count: rest,
        });
    }
    let mut padding = decoder.padding;
    if rest > 0 {
        padding.push(decoder.pos..payload.len());
    }
    Ok((value, padding))
}

struct Decoder<'de> {
    input: &'de [u8],
    pos: usize,
    order: ByteOrder,
    /// Alignment padding skipped so far.
    padding: Vec<std::ops::Range<usize>>,
}

impl<'de> Decoder<'de> {
    fn take(&mut self, n: usize) -> Result<&'de [u8], CdrError> {
        let left = self.input.len() - self.pos;
        if n > left {
            return Err(CdrError::Truncated {
                at: self.pos,
                needed: n - left,
            });
        }
        let bytes = &self.input[self.pos..self.pos + n];
        self.pos += n;
        Ok(bytes)
    }

    /// Skips the padding before a value of `size` bytes (natural alignment).
    fn align(&mut self, size: usize) -> Result<(), CdrError> {
        let (at, pad) = (self.pos, (size - self.pos % size) % size);
        self.take(pad)?;
        if pad > 0 {
            self.padding.push(at..at + pad);
        }
        Ok(())
    }

    fn array<const N: usize>(&mut self) -> Result<[u8; N], CdrError> {
        self.align(N)?;
        let mut out = [0; N];
        out.copy_from_slice(self.take(N)?);
        if self.order == ByteOrder::Big {
            out.reverse();
        }
        // Little-endian from here on.
        Ok(out)
    }

    fn length(&mut self) -> Result<(usize, usize), CdrError> {
        let at = self.pos;
        Ok((u32::from_le_bytes(self.array()?) as usize, at))
    }

    fn string(&mut self) -> Result<&'de str, CdrError> {
        let (len, at) = self.length()?;
        if len == 0 {
            return Err(CdrError::EmptyString { at });
        }
        let bytes = self.take(len)?;
        let (text, nul) = bytes.split_at(len - 1);
        if nul != [0] {
            return Err(CdrError::Unterminated { at });
        }
        if text.contains(&0) {
            return Err(CdrError::InnerNul { at });
        }
        std::str::from_utf8(text).map_err(|_| CdrError::NotUtf8 { at })
    }
}

macro_rules! number {
    ($method:ident, $visit:ident, $ty:ty) => {
        fn $method<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
            visitor.$visit(<$ty>::from_le_bytes(self.array()?))
        }
    };
}

macro_rules! unsupported {
    ($($method:ident: $what:literal),* $(,)?) => {
        $(fn $method<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, CdrError> {
            Err(CdrError::Unsupported($what))
        })*
    };
}

impl<'de> de::Deserializer<'de> for &mut Decoder<'de> {
    type Error = CdrError;

    number!(deserialize_i16, visit_i16, i16);
    number!(deserialize_u16, visit_u16, u16);
    number!(deserialize_i32, visit_i32, i32);
    number!(deserialize_u32, visit_u32, u32);
    number!(deserialize_i64, visit_i64, i64);
    number!(deserialize_u64, visit_u64, u64);
    number!(deserialize_f32, visit_f32, f32);
    number!(deserialize_f64, visit_f64, f64);

    fn deserialize_u8<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_u8(self.take(1)?[0])
    }

    fn deserialize_i8<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_i8(self.take(1)?[0] as i8)
    }

    fn deserialize_bool<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        let at = self.pos;
        match self.take(1)?[0] {
            0 => visitor.visit_bool(false),
            1 => visitor.visit_bool(true),
            value => Err(CdrError::BadBool { at, value }),
        }
    }

    fn deserialize_str<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_borrowed_str(self.string()?)
    }

    fn deserialize_string<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        self.deserialize_str(visitor)
    }

    fn deserialize_seq<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        let (count, at) = self.length()?;
        let left = self.input.len() - self.pos;
        // Every element of every kumi message takes at least one byte.
        if count > left {
            return Err(CdrError::TooLong { at, count, left });
        }
        visitor.visit_seq(Elements {
            decoder: self,
            left: count,
        })
    }

    fn deserialize_tuple<V: Visitor<'de>>(
        self,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        visitor.visit_seq(Elements {
            decoder: self,
            left: len,
        })
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        self.deserialize_tuple(len, visitor)
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        self.deserialize_tuple(fields.len(), visitor)
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        visitor.visit_newtype_struct(self)
    }

    unsupported!(
        deserialize_any: "self-describing data",
        deserialize_char: "a char",
        deserialize_bytes: "raw bytes",
        deserialize_byte_buf: "raw bytes",
        deserialize_option: "an optional value",
        deserialize_unit: "a unit",
        deserialize_map: "a map",
        deserialize_identifier: "an identifier",
        deserialize_ignored_any: "an ignored value",
    );

    fn deserialize_unit_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _visitor: V,
    ) -> Result<V::Value, CdrError> {
        Err(CdrError::Unsupported("a unit struct"))
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _name: &'static str,
        _variants: &'static [&'static str],
        _visitor: V,
    ) -> Result<V::Value, CdrError> {
        Err(CdrError::Unsupported("an enum"))
    }

    fn is_human_readable(&self) -> bool {
        false
    }
}

/// The elements of a sequence, tuple or struct, in order.
struct Elements<'a, 'de> {
    decoder: &'a mut Decoder<'de>,
    left: usize,
}

impl<'de> SeqAccess<'de> for Elements<'_, 'de> {
    type Error = CdrError;

    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, CdrError> {
        if self.left == 0 {
            return Ok(None);
        }
        self.left -= 1;
        seed.deserialize(&mut *self.decoder).map(Some)
    }

    fn size_hint(&self) -> Option<usize> {
        Some(self.left)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry_msgs::PoseStamped;
    use crate::sensor_msgs::JointState;
    use crate::std_msgs::{Bool, Float64MultiArray, StringMsg};

    /// A `PoseStamped` in frame `base` at (1, 2, 3), identity rotation, written by hand.
    fn pose_bytes(frame: &[u8], length: u32) -> Vec<u8> {
        let mut b = Vec::new();
        b.extend(7i32.to_le_bytes()); // stamp.sec
        b.extend(9u32.to_le_bytes()); // stamp.nanosec
        b.extend(length.to_le_bytes());
        b.extend(frame);
        while b.len() % 8 != 0 {
            b.push(0);
        }
        for v in [1.0f64, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0] {
            b.extend(v.to_le_bytes());
        }
        b
    }

    #[test]
    fn decodes_a_message_written_by_hand() {
        let p: PoseStamped = from_bytes(&pose_bytes(b"base\0", 5), ByteOrder::Little).unwrap();
        assert_eq!(p.header.frame_id, "base");
        assert_eq!((p.header.stamp.sec, p.header.stamp.nanosec), (7, 9));
        assert_eq!(p.pose.position.z, 3.0);
        assert_eq!(p.pose.orientation.w, 1.0);
        // Fast DDS leaves alignment padding as it finds it: its content is not checked, and
        // it is reported.
        let mut b = pose_bytes(b"base\0", 5);
        b[21] = 0xAB;
        let (q, padding) = decode_with_padding::<PoseStamped>(&b, ByteOrder::Little).unwrap();
        assert_eq!(q, p);
        assert_eq!(padding.len(), 1);
        assert_eq!((padding[0].start, padding[0].end), (17, 24));
    }

    #[test]
    fn big_endian_payloads_decode_too() {
        // Float64MultiArray: no dimensions, data_offset 0, one value (aligned to 8 bytes).
        let b = [
            0u32.to_be_bytes().as_slice(),
            &0u32.to_be_bytes(),
            &1u32.to_be_bytes(),
            &[0; 4],
            &2.5f64.to_be_bytes(),
        ]
        .concat();
        let v: Float64MultiArray = from_bytes(&b, ByteOrder::Big).unwrap();
        assert_eq!(v.data, vec![2.5]);
    }

    #[test]
    fn refuses_what_lenient_decoders_accept() {
        // Finding 3: a zero string length shifted every later field ("a goal nobody sent").
        let err = from_bytes::<PoseStamped>(&pose_bytes(b"", 0), ByteOrder::Little);
        assert_eq!(err.unwrap_err(), CdrError::EmptyString { at: 8 });
        // A string without its NUL.
        let err = from_bytes::<PoseStamped>(&pose_bytes(b"base", 4), ByteOrder::Little);
        assert_eq!(err.unwrap_err(), CdrError::Unterminated { at: 8 });
        let err = from_bytes::<StringMsg>(&[3, 0, 0, 0, b'a', 0, b'b'], ByteOrder::Little);
        assert_eq!(err.unwrap_err(), CdrError::Unterminated { at: 0 });
        let err = from_bytes::<StringMsg>(&[3, 0, 0, 0, b'a', 0, 0], ByteOrder::Little);
        assert_eq!(err.unwrap_err(), CdrError::InnerNul { at: 0 });
        // The last byte missing.
        let full = pose_bytes(b"base\0", 5);
        let err = from_bytes::<PoseStamped>(&full[..full.len() - 1], ByteOrder::Little);
        assert_eq!(
            err.unwrap_err(),
            CdrError::Truncated {
                at: full.len() - 8,
                needed: 1
            }
        );
        // Bytes after the end (other than zero padding to a multiple of 4).
        let err =
            from_bytes::<PoseStamped>(&[full.as_slice(), &[0; 8]].concat(), ByteOrder::Little);
        assert!(matches!(err, Err(CdrError::Trailing { count: 8, .. })));
        assert!(
            from_bytes::<Bool>(&[1, 0, 0, 0], ByteOrder::Little)
                .unwrap()
                .data
        );
        assert!(from_bytes::<Bool>(&[1, 0, 0], ByteOrder::Little).is_err());
        assert_eq!(
            from_bytes::<Bool>(&[2], ByteOrder::Little).unwrap_err(),
            CdrError::BadBool { at: 0, value: 2 }
        );
        // A sequence longer than the message.
        let mut js = vec![0u8; 8];
        js.extend(1u32.to_le_bytes());
        js.push(0); // frame "" ... then names: claims a billion
        js.extend([0, 0, 0]);
        js.extend(1_000_000_000u32.to_le_bytes());
        assert!(matches!(
            from_bytes::<JointState>(&js, ByteOrder::Little),
            Err(CdrError::TooLong {
                count: 1_000_000_000,
                ..
            })
        ));
        assert!(from_bytes::<JointState>(&[], ByteOrder::Little).is_err());
    }
}
