//! Decoding a message's long list in one allocation (DESIGN.md §8: inserts at millions of
//! triangles a second). serde's own `Vec` reserves at most 1 MiB up front, whatever length the
//! frame announces, so that a few bytes claiming billions of elements cannot take the memory; an
//! insert of 10,000 triangles (144 bytes each in memory) then grows and copies on the way. Here
//! the announced length is believed up to [`MAX_PREALLOCATED`] elements: a lying frame still
//! costs at most that, and a true one longer than it grows as before.

use serde::de::{Deserializer, SeqAccess, Visitor};
use serde::{Deserialize, Serialize, Serializer};

/// Elements reserved before any is read, at most: a few MiB of the largest element.
pub const MAX_PREALLOCATED: usize = 16_384;

/// `#[serde(with = "crate::preallocated")]` on a `Vec<T>` field: written as serde writes a
/// `Vec`, read with the announced length reserved.
pub fn serialize<T: Serialize, S: Serializer>(
    items: &[T],
    serializer: S,
) -> Result<S::Ok, S::Error> {
    serializer.collect_seq(items)
}

pub fn deserialize<'de, T, D>(deserializer: D) -> Result<Vec<T>, D::Error>
where
    T: Deserialize<'de>,
    D: Deserializer<'de>,
{
    struct Items<T>(std::marker::PhantomData<T>);

    impl<'de, T: Deserialize<'de>> Visitor<'de> for Items<T> {
        type Value = Vec<T>;

        fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
            f.write_str("a sequence")
        }

        fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Vec<T>, A::Error> {
            let announced = seq.size_hint().unwrap_or(0);
            let mut items = Vec::with_capacity(announced.min(MAX_PREALLOCATED));
            while let Some(item) = seq.next_element()? {
                items.push(item);
            }
            Ok(items)
        }
    }

    deserializer.deserialize_seq(Items(std::marker::PhantomData))
}

#[cfg(test)]
mod tests {
    use serde::{Deserialize, Serialize};

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Batch {
        #[serde(with = "super")]
        items: Vec<[u64; 4]>,
    }

    /// Written as a plain `Vec` is, so the wire is unchanged, and read back whole.
    #[test]
    fn a_list_round_trips_in_the_plain_vec_encoding() {
        let batch = Batch {
            items: (0..40_000u64).map(|i| [i, i + 1, i + 2, i + 3]).collect(),
        };
        let bytes = postcard::to_stdvec(&batch).unwrap();
        #[derive(Serialize)]
        struct Plain<'a> {
            items: &'a Vec<[u64; 4]>,
        }
        let plain = postcard::to_stdvec(&Plain {
            items: &batch.items,
        })
        .unwrap();
        assert_eq!(bytes, plain);
        assert_eq!(postcard::from_bytes::<Batch>(&bytes).unwrap(), batch);
    }

    /// A frame announcing far more elements than it holds fails to decode, having reserved no
    /// more than the cap.
    #[test]
    fn a_length_that_lies_is_an_error_not_an_allocation() {
        let mut bytes = Vec::new();
        // postcard's varint for u32::MAX elements, then one element's worth of bytes.
        bytes.extend_from_slice(&[0xff, 0xff, 0xff, 0xff, 0x0f]);
        bytes.extend_from_slice(&[1, 2, 3, 4]);
        assert!(postcard::from_bytes::<Batch>(&bytes).is_err());
    }
}
