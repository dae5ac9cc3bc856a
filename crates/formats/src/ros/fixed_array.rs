//! ROS's fixed-length arrays (`float64[36]`, `uint8[1206]`), which serde derives only
//! up to 32 values.

use serde::{Deserialize, Serialize};

/// A ROS fixed-length array `T[N]`: serde derives arrays only up to 32; CDR and ROS 1
/// write it as N values and no length. Holds exactly N values.
#[derive(Clone, Debug, PartialEq)]
pub struct FixedArray<T, const N: usize>(pub Vec<T>);

impl<T: Serialize, const N: usize> Serialize for FixedArray<T, N> {
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{Error, SerializeTuple};
        if self.0.len() != N {
            return Err(S::Error::custom(format!(
                "{} values in an array of {N}",
                self.0.len()
            )));
        }
        let mut tuple = serializer.serialize_tuple(N)?;
        for v in &self.0 {
            tuple.serialize_element(v)?;
        }
        tuple.end()
    }
}

impl<'de, T: Deserialize<'de>, const N: usize> Deserialize<'de> for FixedArray<T, N> {
    fn deserialize<D: serde::Deserializer<'de>>(deserializer: D) -> Result<Self, D::Error> {
        struct Values<T, const N: usize>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>, const N: usize> serde::de::Visitor<'de> for Values<T, N> {
            type Value = FixedArray<T, N>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                write!(f, "{N} values")
            }
            fn visit_seq<A: serde::de::SeqAccess<'de>>(
                self,
                mut seq: A,
            ) -> Result<FixedArray<T, N>, A::Error> {
                let mut out = Vec::with_capacity(N);
                for i in 0..N {
                    let value = seq.next_element()?;
                    out.push(value.ok_or_else(|| serde::de::Error::invalid_length(i, &self))?);
                }
                Ok(FixedArray(out))
            }
        }
        deserializer.deserialize_tuple(N, Values::<T, N>(std::marker::PhantomData))
    }
}
