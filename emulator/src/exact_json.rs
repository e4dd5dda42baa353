//! JSON read back bit for bit. serde_json writes every f64 with its shortest round-trip
//! digits, but its default parser may land one ulp off (issue #36: a scenario's
//! `engine_thrust_scale = 0.9985811925219601` came back `0.99858119252196`, and a
//! replay diverged at step 1). Its `float_roundtrip` feature would fix that everywhere,
//! and with it change how the committed surrogate model file parses and move the frozen
//! surrogate digest; so what the bench writes and reads back (run configurations in
//! reports and log headers, campaign case records) is parsed here instead: each
//! number's own text goes through Rust's exact parser.

use serde::de::{DeserializeOwned, Error as _};
use serde::{Deserialize, Deserializer};
use serde_json::value::RawValue;
use serde_json::{Map, Number, Value};

/// Parses `text` into a [`Value`] whose every number is the exact one its digits name.
pub fn value_from_str(text: &str) -> Result<Value, serde_json::Error> {
    let mut de = serde_json::Deserializer::from_str(text);
    let Exact(v) = Exact::deserialize(&mut de)?;
    de.end()?;
    Ok(v)
}

/// Parses `text` into a `T` (see [`value_from_str`]).
pub fn from_str<T: DeserializeOwned>(text: &str) -> Result<T, serde_json::Error> {
    serde_json::from_value(value_from_str(text)?)
}

/// A value parsed from its raw text.
struct Exact(Value);

impl<'de> Deserialize<'de> for Exact {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let raw: &'de RawValue = Deserialize::deserialize(d)?;
        exact(raw.get()).map(Exact).map_err(D::Error::custom)
    }
}

/// The value of one JSON text (already checked well-formed by the enclosing parse):
/// containers element by element, numbers by their digits, the rest as serde_json
/// parses them.
fn exact(text: &str) -> Result<Value, serde_json::Error> {
    match text.as_bytes().first() {
        Some(b'{') => {
            let map: Vec<(String, Exact)> = serde_json::from_str::<ExactMap>(text)?.0;
            let mut out = Map::new();
            for (k, Exact(v)) in map {
                // A repeated key: the last wins, as in serde_json's own `Value`.
                out.insert(k, v);
            }
            Ok(Value::Object(out))
        }
        Some(b'[') => {
            let items: Vec<Exact> = serde_json::from_str(text)?;
            Ok(Value::Array(items.into_iter().map(|Exact(v)| v).collect()))
        }
        Some(b'-' | b'0'..=b'9') => number(text),
        _ => serde_json::from_str(text),
    }
}

/// An object's entries in file order.
struct ExactMap(Vec<(String, Exact)>);

impl<'de> Deserialize<'de> for ExactMap {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Entries;
        impl<'de> serde::de::Visitor<'de> for Entries {
            type Value = ExactMap;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a JSON object")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut map: A,
            ) -> Result<ExactMap, A::Error> {
                let mut out = Vec::new();
                while let Some(entry) = map.next_entry::<String, Exact>()? {
                    out.push(entry);
                }
                Ok(ExactMap(out))
            }
        }
        d.deserialize_map(Entries)
    }
}

/// A number: an integer as serde_json reads one (u64, else i64), anything else (a
/// fraction, an exponent, an integer beyond 64 bits) as the f64 nearest its digits.
fn number(text: &str) -> Result<Value, serde_json::Error> {
    let bad = |why: String| serde_json::Error::custom(format!("number `{text}`: {why}"));
    if !text.contains(['.', 'e', 'E']) {
        if let Ok(u) = text.parse::<u64>() {
            return Ok(Value::Number(u.into()));
        }
        if let Ok(i) = text.parse::<i64>() {
            return Ok(Value::Number(i.into()));
        }
    }
    let x: f64 = text.parse().map_err(|e| bad(format!("{e}")))?;
    Number::from_f64(x)
        .map(Value::Number)
        .ok_or_else(|| bad("out of range".into()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_digits_serde_json_misreads_come_back_exact() {
        // serde_json's default parser reads these one ulp off.
        for x in [
            0.9985811925219601f64,
            1.0715660391465826e-75,
            -1.81996730402717e-179,
        ] {
            let text = serde_json::to_string(&serde_json::json!({"a": [x, {"b": x}]})).unwrap();
            let v = value_from_str(&text).unwrap();
            assert_eq!(v["a"][0].as_f64().unwrap().to_bits(), x.to_bits(), "{text}");
            assert_eq!(v["a"][1]["b"].as_f64().unwrap().to_bits(), x.to_bits());
        }
    }

    #[test]
    fn integers_strings_and_literals_are_serde_json_s() {
        let text = r#"{"u": 18446744073709551615, "i": -3, "big": 1e400, "s": "x\"y", "t": true, "n": null}"#;
        assert!(value_from_str(text).is_err(), "1e400 is out of range");
        let text = r#"{"u": 18446744073709551615, "i": -3, "f": 2.5, "s": "x\"y", "t": true, "n": null, "o": {}, "a": []}"#;
        let v = value_from_str(text).unwrap();
        assert_eq!(v, serde_json::from_str::<Value>(text).unwrap());
        assert!(v["u"].is_u64() && v["i"].is_i64() && v["f"].is_f64());
        assert!(value_from_str("{\"a\": 1} x").is_err());
        assert!(value_from_str("[1, 2").is_err());
    }
}
