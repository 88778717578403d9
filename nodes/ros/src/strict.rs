//! Subscriptions that decode strictly: a message from the wire is decoded by
//! [`kumi_msgs::cdr`], every byte accounted for, or refused whole with the reason (issue 10,
//! finding 3: ros2-client's decoder accepted a zero string length and shifted every later
//! field).
//!
//! The DDS reader is RustDDS's, with an adapter that hands over the payload bytes and their
//! byte order untouched. Beside it, a ros2-client subscription of the same topic is kept so
//! that the node lists the subscription in the ROS graph (`ros2 node info`); its samples are
//! dropped undecoded as they arrive, so that it holds no memory.

use std::convert::Infallible;

use kumi_msgs::cdr::{self, ByteOrder};
use kumi_msgs::RosMessage;
use ros2_client::dds::rustdds::{no_key, RepresentationIdentifier};
use ros2_client::{Gid, Subscription};

/// A payload as it arrived: its byte order (`None`: not plain CDR) and its bytes after the
/// encapsulation header.
#[derive(Debug, Clone)]
pub struct RawSample {
    pub order: Option<ByteOrder>,
    pub bytes: Vec<u8>,
}

/// The RustDDS adapter that keeps payloads as bytes.
pub struct RawAdapter;

/// Its decoder: a copy of the bytes.
#[derive(Debug, Clone, Copy)]
pub struct RawDecoder;

impl no_key::DeserializerAdapter<RawSample> for RawAdapter {
    type Error = Infallible;
    type Decoded = RawSample;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &[
            RepresentationIdentifier::CDR_LE,
            RepresentationIdentifier::CDR_BE,
        ]
    }

    fn transform_decoded(decoded: RawSample) -> RawSample {
        decoded
    }
}

impl no_key::DefaultDecoder<RawSample> for RawAdapter {
    type Decoder = RawDecoder;
    const DECODER: RawDecoder = RawDecoder;
}

impl<'de> no_key::Decode<'de, RawSample> for RawDecoder {
    type Error = Infallible;

    fn decode_bytes(
        self,
        input_bytes: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> Result<RawSample, Infallible> {
        let order = if encoding == RepresentationIdentifier::CDR_LE {
            Some(ByteOrder::Little)
        } else if encoding == RepresentationIdentifier::CDR_BE {
            Some(ByteOrder::Big)
        } else {
            None
        };
        Ok(RawSample {
            order,
            bytes: input_bytes.to_vec(),
        })
    }
}

/// Decodes a payload strictly as `M`.
pub fn decode<M: RosMessage>(sample: &RawSample) -> Result<M, String> {
    let order = sample
        .order
        .ok_or_else(|| "not a plain CDR payload".to_string())?;
    cdr::from_bytes(&sample.bytes, order).map_err(|e| format!("{} ({e})", M::NAME))
}

/// What the graph's subscription decodes its samples to: nothing (it reads no byte).
pub struct Unread;

impl<'de> serde::Deserialize<'de> for Unread {
    fn deserialize<D: serde::Deserializer<'de>>(_: D) -> Result<Self, D::Error> {
        Ok(Unread)
    }
}

/// A sample as it arrived, with its writer and when the writer stamped it.
#[derive(Debug, Clone)]
pub struct RawChange {
    pub sample: RawSample,
    pub writer: Gid,
    /// The writer's source timestamp [ns since the Unix epoch], when it sent one.
    pub source_time_ns: Option<u64>,
}

/// A subscription that hands over payloads undecoded (for a recorder, or to decode strictly).
pub struct RawSubscription {
    reader: no_key::SimpleDataReader<RawSample, RawAdapter>,
    graph: Subscription<Unread>,
}

impl RawSubscription {
    pub(crate) fn new(
        reader: no_key::SimpleDataReader<RawSample, RawAdapter>,
        graph: Subscription<Unread>,
    ) -> Self {
        Self { reader, graph }
    }

    /// The next waiting sample; `None` when none waits; `Some(Err(why))` when the reader
    /// failed.
    pub fn take(&self) -> Option<Result<RawChange, String>> {
        for _ in 0..1000 {
            if !matches!(self.graph.take(), Ok(Some(_))) {
                break;
            }
        }
        self.reader.drain_read_notifications();
        match self.reader.try_take_one() {
            Ok(None) => None,
            Ok(Some(change)) => {
                let writer = Gid::from(change.writer_guid);
                let source_time_ns = change
                    .source_timestamp()
                    .and_then(|t| nanos_of_ticks(t.to_ticks()));
                Some(Ok(RawChange {
                    sample: change.into_value(),
                    writer,
                    source_time_ns,
                }))
            }
            Err(e) => Some(Err(format!("{e:?}"))),
        }
    }
}

/// A DDS timestamp in ticks (seconds in the high 32 bits, 2^-32 s in the low) in
/// nanoseconds; `None` for DDS's invalid and infinite times.
fn nanos_of_ticks(ticks: u64) -> Option<u64> {
    (ticks < 0xFFFF_FFFF_0000_0000)
        .then(|| ((ticks >> 32) * 1_000_000_000) + (((ticks & 0xFFFF_FFFF) * 1_000_000_000) >> 32))
}

/// A strictly decoding subscription to `M`.
pub struct StrictSubscription<M> {
    raw: RawSubscription,
    _message: std::marker::PhantomData<M>,
}

impl<M: RosMessage> StrictSubscription<M> {
    pub(crate) fn new(raw: RawSubscription) -> Self {
        Self {
            raw,
            _message: std::marker::PhantomData,
        }
    }

    /// The next waiting message and its writer; `None` when none waits; `Some(Err(why))` for
    /// one that did not decode exactly (it is consumed).
    pub fn take(&self) -> Option<Result<(M, Gid), String>> {
        self.raw
            .take()
            .map(|taken| taken.and_then(|c| decode::<M>(&c.sample).map(|m| (m, c.writer))))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dds_timestamps_convert_to_nanoseconds() {
        assert_eq!(nanos_of_ticks(0), Some(0));
        assert_eq!(
            nanos_of_ticks((1_700_000_000 << 32) + (1 << 31)),
            Some(1_700_000_000_500_000_000)
        );
        assert_eq!(nanos_of_ticks(u64::MAX), None);
        assert_eq!(nanos_of_ticks(u64::MAX - 1), None);
    }
}
