//! The field names of a document type, read from its `Deserialize` implementation, so lists
//! of fields (a sweep's axes) follow the type instead of being written out beside it.

use serde::de::{self, Deserialize, Deserializer, Visitor};

/// The fields `T` deserializes from (a struct's, as serde names them); empty for a type that
/// is not a struct.
pub fn field_names<'de, T: Deserialize<'de>>() -> &'static [&'static str] {
    let mut fields: &'static [&'static str] = &[];
    // The struct's `deserialize` hands its field list to `deserialize_struct`, which records it
    // and stops.
    let _ = T::deserialize(FieldNames(&mut fields));
    fields
}

struct FieldNames<'a>(&'a mut &'static [&'static str]);

#[derive(Debug)]
struct Stop;

impl std::fmt::Display for Stop {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("field names read")
    }
}

impl std::error::Error for Stop {}

impl de::Error for Stop {
    fn custom<M: std::fmt::Display>(_: M) -> Self {
        Stop
    }
}

impl<'de> Deserializer<'de> for FieldNames<'_> {
    type Error = Stop;

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _name: &'static str,
        fields: &'static [&'static str],
        _visitor: V,
    ) -> Result<V::Value, Stop> {
        *self.0 = fields;
        Err(Stop)
    }

    fn deserialize_any<V: Visitor<'de>>(self, _visitor: V) -> Result<V::Value, Stop> {
        Err(Stop)
    }

    serde::forward_to_deserialize_any! {
        bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes byte_buf
        option unit unit_struct newtype_struct seq tuple tuple_struct map enum identifier
        ignored_any
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_struct_s_fields_as_serde_names_them() {
        let fields = field_names::<crate::TrainSpec>();
        for field in ["algorithm", "steps", "seed", "config", "settle_s", "hold_s"] {
            assert!(fields.contains(&field), "{field} in {fields:?}");
        }
        assert!(field_names::<crate::PpoConfig>().contains(&"minibatch_size"));
        assert!(field_names::<u64>().is_empty());
    }
}
