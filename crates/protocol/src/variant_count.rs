//! The number of variants of a message enum, read from its serde derive rather than kept by hand:
//! serde hands every variant name to `Deserializer::deserialize_enum`, so a deserializer that only
//! listens there learns them.

use std::cell::Cell;
use std::fmt;

use serde::Deserializer;
use serde::de::{self, DeserializeOwned, Visitor};

/// How many variants the enum `M` has (0 when `M` is not an enum).
pub fn variant_count<M: DeserializeOwned>() -> u32 {
    let listener = VariantListener(Cell::new(0));
    let _ = M::deserialize(&listener);
    listener.0.get()
}

struct VariantListener(Cell<u32>);

/// What the listener answers every request with: it never produces a value.
#[derive(Debug)]
struct Listened;

impl fmt::Display for Listened {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("variants listened to")
    }
}

impl std::error::Error for Listened {}

impl de::Error for Listened {
    fn custom<T: fmt::Display>(_: T) -> Self {
        Listened
    }
}

impl<'de> Deserializer<'de> for &VariantListener {
    type Error = Listened;

    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, Listened> {
        Err(Listened)
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _name: &'static str,
        variants: &'static [&'static str],
        _: V,
    ) -> Result<V::Value, Listened> {
        self.0.set(variants.len() as u32);
        Err(Listened)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map struct identifier
        ignored_any
    }
}

#[cfg(test)]
mod tests {
    use serde::Deserialize;

    use super::*;

    #[derive(Deserialize)]
    #[allow(dead_code)] // only counted
    enum Three {
        A,
        B(u32),
        C { x: f32 },
    }

    #[test]
    fn counts_the_variants_of_an_enum() {
        assert_eq!(variant_count::<Three>(), 3);
        assert_eq!(variant_count::<u32>(), 0);
    }
}
