//! Fixed-size arrays read at exactly their length. serde reads `[f64; 4]` by taking
//! four elements, and toml 0.8 then drops whatever follows unread: a fifth element,
//! even `"x"`, vanished silently (issue #36) while a short array was refused. A field
//! read through [`deserialize`] refuses any other length, naming its key and both
//! lengths, in TOML and JSON alike; nested arrays (`[[f64; 3]; 4]`) are checked at
//! every level.

/// One reader per fixed-size array field, refusing another length by the field's
/// dotted name: `fixed_len! { name: [f64; 3] => "table.key", ... }` defines `fn name`
/// for `#[serde(deserialize_with = "name")]`. The caller imports `serde::Deserializer`.
macro_rules! fixed_len {
    ($($name:ident: $ty:ty => $key:literal),* $(,)?) => {$(
        fn $name<'de, D: Deserializer<'de>>(d: D) -> Result<$ty, D::Error> {
            crate::fixed_len::deserialize(d, $key)
        }
    )*};
}
pub(crate) use fixed_len;

use serde::de::{DeserializeSeed, Error as _, IgnoredAny, SeqAccess, Visitor};
use serde::{Deserialize, Deserializer};
use std::marker::PhantomData;

/// Reads a fixed-size array field at exactly its length; `key` names the field in the
/// error. Use through a function per field:
/// `fn window_s<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 2], D::Error> {
/// fixed_len::deserialize(d, "window_s") }` and `#[serde(deserialize_with = "window_s")]`.
pub fn deserialize<'de, D, T>(d: D, key: &'static str) -> Result<T, D::Error>
where
    D: Deserializer<'de>,
    T: Fixed<'de>,
{
    T::read(d, key)
}

/// A value whose arrays have a fixed length: a number, or an array of such values.
pub trait Fixed<'de>: Sized {
    /// Reads the value, refusing an array of another length.
    fn read<D: Deserializer<'de>>(d: D, key: &'static str) -> Result<Self, D::Error>;
}

impl<'de> Fixed<'de> for f64 {
    fn read<D: Deserializer<'de>>(d: D, _key: &'static str) -> Result<Self, D::Error> {
        f64::deserialize(d)
    }
}

impl<'de, T: Fixed<'de>, const N: usize> Fixed<'de> for [T; N] {
    fn read<D: Deserializer<'de>>(d: D, key: &'static str) -> Result<Self, D::Error> {
        d.deserialize_seq(Elements::<T, N> {
            key,
            item: PhantomData,
        })
    }
}

/// Reads one element (itself checked).
struct Element<T> {
    key: &'static str,
    item: PhantomData<T>,
}

impl<'de, T: Fixed<'de>> DeserializeSeed<'de> for Element<T> {
    type Value = T;
    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<T, D::Error> {
        T::read(d, self.key)
    }
}

/// Reads every element of an array, then checks how many there were.
struct Elements<T, const N: usize> {
    key: &'static str,
    item: PhantomData<T>,
}

impl<'de, T: Fixed<'de>, const N: usize> Visitor<'de> for Elements<T, N> {
    type Value = [T; N];

    fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        write!(f, "an array of {N} elements ({})", self.key)
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<[T; N], A::Error> {
        let mut items = Vec::with_capacity(N);
        while items.len() < N {
            let seed = Element {
                key: self.key,
                item: PhantomData,
            };
            match seq.next_element_seed(seed)? {
                Some(x) => items.push(x),
                None => break,
            }
        }
        let mut len = items.len();
        // Counted, not read: an extra element of any type is one too many.
        while seq.next_element::<IgnoredAny>()?.is_some() {
            len += 1;
        }
        if len != N {
            return Err(A::Error::custom(format!(
                "`{}` has {len} elements, expected {N}",
                self.key
            )));
        }
        items
            .try_into()
            .map_err(|_| A::Error::custom(format!("`{}`: expected {N} elements", self.key)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;

    fn scale<'de, D: Deserializer<'de>>(d: D) -> Result<[f64; 4], D::Error> {
        deserialize(d, "engine_thrust_scale")
    }

    fn positions<'de, D: Deserializer<'de>>(d: D) -> Result<[[f64; 2]; 2], D::Error> {
        deserialize(d, "positions")
    }

    #[derive(Debug, Deserialize, PartialEq)]
    struct S {
        #[serde(default, deserialize_with = "scale")]
        engine_thrust_scale: [f64; 4],
        #[serde(default, deserialize_with = "positions")]
        positions: [[f64; 2]; 2],
    }

    #[test]
    fn toml_and_json_arrays_of_another_length_are_refused_by_key() {
        let ok: S = toml::from_str("engine_thrust_scale = [1.0, 2.0, 3.0, 4.0]\n").unwrap();
        assert_eq!(ok.engine_thrust_scale, [1.0, 2.0, 3.0, 4.0]);
        for (text, len) in [
            ("engine_thrust_scale = [1.0, 1.0, 1.0, 1.0, \"x\"]", 5),
            ("engine_thrust_scale = [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]", 6),
            ("engine_thrust_scale = [1.0, 1.0, 1.0]", 3),
        ] {
            let e = toml::from_str::<S>(text).unwrap_err().to_string();
            assert!(
                e.contains(&format!(
                    "`engine_thrust_scale` has {len} elements, expected 4"
                )),
                "{e}"
            );
        }
        let e = toml::from_str::<S>("positions = [[1.0, 2.0], [1.0, 2.0, 3.0]]")
            .unwrap_err()
            .to_string();
        assert!(e.contains("`positions` has 3 elements, expected 2"), "{e}");
        let e = serde_json::from_str::<S>(r#"{"engine_thrust_scale": [1, 1, 1, 1, 1]}"#)
            .unwrap_err()
            .to_string();
        assert!(e.contains("has 5 elements, expected 4"), "{e}");
        let e = toml::from_str::<S>("engine_thrust_scale = [1.0, 1.0, \"x\", 1.0]")
            .unwrap_err()
            .to_string();
        assert!(e.contains("invalid type"), "{e}");
    }
}
