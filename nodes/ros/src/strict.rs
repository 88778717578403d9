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

/// A strictly decoding subscription to `M`.
pub struct StrictSubscription<M> {
    reader: no_key::SimpleDataReader<RawSample, RawAdapter>,
    graph: Subscription<Unread>,
    _message: std::marker::PhantomData<M>,
}

impl<M: RosMessage> StrictSubscription<M> {
    pub(crate) fn new(
        reader: no_key::SimpleDataReader<RawSample, RawAdapter>,
        graph: Subscription<Unread>,
    ) -> Self {
        Self {
            reader,
            graph,
            _message: std::marker::PhantomData,
        }
    }

    /// The next waiting message and its writer; `None` when none waits; `Some(Err(why))` for
    /// one that did not decode exactly (it is consumed).
    pub fn take(&self) -> Option<Result<(M, Gid), String>> {
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
                Some(decode::<M>(&change.into_value()).map(|m| (m, writer)))
            }
            Err(e) => Some(Err(format!("{e:?}"))),
        }
    }
}
