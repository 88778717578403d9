//! Serde for fixed-size arrays of any length: CDR writes `float64[36]` as 36 values with no
//! length prefix, which is serde's tuple form (serde's own array support stops at 32).

use std::fmt;
use std::marker::PhantomData;

use serde::de::{Error, SeqAccess, Visitor};
use serde::ser::SerializeTuple;
use serde::{Deserializer, Serializer};

pub fn serialize<S: Serializer, const N: usize>(
    values: &[f64; N],
    s: S,
) -> Result<S::Ok, S::Error> {
    let mut tuple = s.serialize_tuple(N)?;
    for v in values {
        tuple.serialize_element(v)?;
    }
    tuple.end()
}

pub fn deserialize<'de, D: Deserializer<'de>, const N: usize>(d: D) -> Result<[f64; N], D::Error> {
    struct ArrayVisitor<const N: usize>(PhantomData<[f64; N]>);

    impl<'de, const N: usize> Visitor<'de> for ArrayVisitor<N> {
        type Value = [f64; N];

        fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
            write!(f, "an array of {N} floats")
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Self::Value, A::Error> {
            let mut out = [0.0; N];
            for (i, slot) in out.iter_mut().enumerate() {
                *slot = seq
                    .next_element()?
                    .ok_or_else(|| A::Error::invalid_length(i, &self))?;
            }
            Ok(out)
        }
    }

    d.deserialize_tuple(N, ArrayVisitor::<N>(PhantomData))
}
