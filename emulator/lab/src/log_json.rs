//! The per-step JSON messages of the MCAP log and their JSON schemas, both built from
//! the core's table of record fields ([`oils_emulator::log_fields::FIELDS`]): a
//! message holds every field of its topic at the field's path, its schema names
//! exactly those (all required, nothing else allowed), and reading a message back sets
//! every field the table can set. Nothing here names a field by hand.

use oils_emulator::log_fields::{Field, Kind, Sample, Topic, Value, FIELDS};
use oils_emulator::recorder::Record;
use serde::ser::{SerializeMap, SerializeSeq};
use serde::{Serialize, Serializer};
use serde_json::value::RawValue;
use std::collections::BTreeMap;
use std::sync::OnceLock;

/// A message's shape: objects by key, in table order.
enum Node {
    /// A JSON object.
    Object(Members),
    /// An array of `n` objects: element i of each field inside goes to object i.
    Objects(usize, Members),
    /// A field.
    Leaf(&'static Field),
}

/// An object's members, in table order.
type Members = Vec<(&'static str, Node)>;

/// The shapes of the six per-step messages, built once from the table.
fn shapes() -> &'static [(Topic, Members)] {
    static SHAPES: OnceLock<Vec<(Topic, Members)>> = OnceLock::new();
    SHAPES.get_or_init(|| {
        Topic::ALL
            .iter()
            .map(|&topic| {
                let mut root = Vec::new();
                for f in FIELDS.iter().filter(|f| f.topic == topic) {
                    let segments: Vec<&'static str> = f.path.split('.').collect();
                    insert(&mut root, &segments, f);
                }
                (topic, root)
            })
            .collect()
    })
}

fn shape(topic: Topic) -> &'static [(&'static str, Node)] {
    shapes()
        .iter()
        .find(|(t, _)| *t == topic)
        .map(|(_, s)| s.as_slice())
        .unwrap_or(&[])
}

/// Puts `field` at `path` under `children`. The table is static and its shape is
/// checked by the tests below; a path that clashes with another is a bug in it.
fn insert(children: &mut Members, path: &[&'static str], field: &'static Field) {
    let (segment, rest) = (path[0], &path[1..]);
    if rest.is_empty() {
        children.push((segment, Node::Leaf(field)));
        return;
    }
    let (name, objects) = match segment.strip_suffix("[]") {
        Some(name) => (name, true),
        None => (segment, false),
    };
    let at = match children.iter().position(|(k, _)| *k == name) {
        Some(at) => at,
        None => {
            let node = match objects {
                true => Node::Objects(field.count(), Vec::new()),
                false => Node::Object(Vec::new()),
            };
            children.push((name, node));
            children.len() - 1
        }
    };
    match &mut children[at].1 {
        Node::Object(inner) | Node::Objects(_, inner) => insert(inner, rest, field),
        Node::Leaf(other) => panic!(
            "log field table: {} under the value {}",
            field.path, other.path
        ),
    }
}

/// The schema name of a topic's messages.
pub fn schema_name(topic: Topic) -> &'static str {
    match topic {
        Topic::Telemetry => "oils.Telemetry",
        Topic::Command => "oils.Command",
        Topic::Truth => "oils.TrueState",
        Topic::Propulsion => "oils.Propulsion",
        Topic::Timing => "oils.StepTiming",
        Topic::Devices => "oils.Devices",
    }
}

// ---------------------------------------------------------------------------------------
// Writing.

/// A topic's message for one record, as a value serde writes.
pub fn message<'a>(topic: Topic, sample: &'a Sample<'a>) -> impl Serialize + 'a {
    Object {
        children: shape(topic),
        sample,
        element: None,
    }
}

struct Object<'a> {
    children: &'static [(&'static str, Node)],
    sample: &'a Sample<'a>,
    /// Inside an array of objects: which element.
    element: Option<usize>,
}

impl Serialize for Object<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut map = s.serialize_map(Some(self.children.len()))?;
        for (key, node) in self.children {
            match node {
                Node::Leaf(f) => map.serialize_entry(
                    key,
                    &Values {
                        field: f,
                        sample: self.sample,
                        element: self.element,
                    },
                )?,
                Node::Object(inner) => map.serialize_entry(
                    key,
                    &Object {
                        children: inner,
                        sample: self.sample,
                        element: self.element,
                    },
                )?,
                Node::Objects(n, inner) => map.serialize_entry(
                    key,
                    &Objects {
                        n: *n,
                        children: inner,
                        sample: self.sample,
                    },
                )?,
            }
        }
        map.end()
    }
}

struct Objects<'a> {
    n: usize,
    children: &'static [(&'static str, Node)],
    sample: &'a Sample<'a>,
}

impl Serialize for Objects<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let mut seq = s.serialize_seq(Some(self.n))?;
        for i in 0..self.n {
            seq.serialize_element(&Object {
                children: self.children,
                sample: self.sample,
                element: Some(i),
            })?;
        }
        seq.end()
    }
}

struct Values<'a> {
    field: &'static Field,
    sample: &'a Sample<'a>,
    element: Option<usize>,
}

impl Serialize for Values<'_> {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        let f = self.field;
        let one = |i| Scalar(f.kind, f.get(self.sample, i));
        match (self.element, f.len) {
            (Some(i), _) => one(i).serialize(s),
            (None, None) => one(0).serialize(s),
            (None, Some(n)) => {
                let mut seq = s.serialize_seq(Some(n))?;
                for i in 0..n {
                    seq.serialize_element(&one(i))?;
                }
                seq.end()
            }
        }
    }
}

struct Scalar(Kind, Value);

impl Serialize for Scalar {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match (self.0, self.1) {
            // serde_json writes a non-finite float as null.
            (_, Value::F64(x)) => s.serialize_f64(x),
            (_, Value::Bool(b)) => s.serialize_bool(b),
            (Kind::Hex, Value::U64(n)) => {
                let mut buf = [0u8; 16];
                s.serialize_str(hex(n, &mut buf))
            }
            (_, Value::U64(n)) => s.serialize_u64(n),
            (_, Value::I64(n)) => s.serialize_i64(n),
            (_, Value::Absent) => s.serialize_none(),
        }
    }
}

/// `n` as 16 lower-case hex digits, in `buf`.
fn hex(n: u64, buf: &mut [u8; 16]) -> &str {
    const DIGITS: &[u8; 16] = b"0123456789abcdef";
    for (i, b) in buf.iter_mut().enumerate() {
        *b = DIGITS[((n >> (60 - 4 * i)) & 0xf) as usize];
    }
    // ASCII digits only.
    std::str::from_utf8(buf).unwrap_or_default()
}

// ---------------------------------------------------------------------------------------
// Schemas.

/// The JSON schema of a topic's messages: every field of the topic, each required, no
/// other property allowed, arrays of their exact length.
pub fn schema(topic: Topic) -> serde_json::Value {
    let mut s = object_schema(shape(topic), false);
    s["title"] = schema_name(topic).into();
    s
}

/// `element`: inside an array of objects, where a field holds one of its values.
fn object_schema(children: &[(&'static str, Node)], element: bool) -> serde_json::Value {
    let mut props = serde_json::Map::new();
    for (key, node) in children {
        let s = match node {
            Node::Leaf(f) => match (element, f.len) {
                (true, _) | (false, None) => kind_schema(f.kind),
                (false, Some(n)) => array_schema(kind_schema(f.kind), n),
            },
            Node::Object(inner) => object_schema(inner, element),
            Node::Objects(n, inner) => array_schema(object_schema(inner, true), *n),
        };
        props.insert(key.to_string(), s);
    }
    let required: Vec<&str> = children.iter().map(|(k, _)| *k).collect();
    serde_json::json!({
        "type": "object",
        "properties": props,
        "required": required,
        "additionalProperties": false,
    })
}

fn array_schema(items: serde_json::Value, n: usize) -> serde_json::Value {
    serde_json::json!({"type": "array", "items": items, "minItems": n, "maxItems": n})
}

fn kind_schema(kind: Kind) -> serde_json::Value {
    match kind {
        Kind::F64 => serde_json::json!({"type": ["number", "null"]}),
        Kind::Bool => serde_json::json!({"type": "boolean"}),
        Kind::U32 | Kind::U64 | Kind::I64 => serde_json::json!({"type": "integer"}),
        Kind::Hex => serde_json::json!({"type": "string"}),
        Kind::OptU64 | Kind::OptI64 => serde_json::json!({"type": ["integer", "null"]}),
    }
}

// ---------------------------------------------------------------------------------------
// Reading.

/// Sets every field of `rec` a topic's message `json` holds. `format`: the file's
/// message format (`oils-mcap-N`); fields newer than it may be missing. Errors name the
/// field.
pub fn read_message(
    topic: Topic,
    json: &[u8],
    format: u32,
    rec: &mut Record,
) -> Result<(), String> {
    let raw: &RawValue = serde_json::from_slice(json).map_err(|e| e.to_string())?;
    read_object(shape(topic), raw, format, rec, None)
}

fn read_object(
    children: &[(&'static str, Node)],
    raw: &RawValue,
    format: u32,
    rec: &mut Record,
    element: Option<usize>,
) -> Result<(), String> {
    let map: BTreeMap<&str, &RawValue> =
        serde_json::from_str(raw.get()).map_err(|e| format!("not an object: {e}"))?;
    for (key, node) in children {
        let Some(value) = map.get(key) else {
            if needed(node, format) {
                return Err(format!("no field `{key}`"));
            }
            continue;
        };
        let within = |e: String| format!("{key}: {e}");
        match node {
            Node::Leaf(f) => read_values(f, value, rec, element).map_err(within)?,
            Node::Object(inner) => {
                read_object(inner, value, format, rec, element).map_err(within)?
            }
            Node::Objects(n, inner) => {
                let items = array(value, *n).map_err(within)?;
                for (i, item) in items.into_iter().enumerate() {
                    read_object(inner, item, format, rec, Some(i)).map_err(within)?;
                }
            }
        }
    }
    Ok(())
}

/// Whether a message in `format` must hold `node` (a field read back in it).
fn needed(node: &Node, format: u32) -> bool {
    match node {
        Node::Leaf(f) => f.setter().is_some() && f.since <= format,
        Node::Object(inner) | Node::Objects(_, inner) => {
            inner.iter().any(|(_, n)| needed(n, format))
        }
    }
}

fn array(raw: &RawValue, n: usize) -> Result<Vec<&RawValue>, String> {
    let items: Vec<&RawValue> =
        serde_json::from_str(raw.get()).map_err(|e| format!("not an array: {e}"))?;
    if items.len() != n {
        return Err(format!("{} elements, not {n}", items.len()));
    }
    Ok(items)
}

fn read_values(
    f: &Field,
    raw: &RawValue,
    rec: &mut Record,
    element: Option<usize>,
) -> Result<(), String> {
    let Some(set) = f.setter() else {
        return Ok(());
    };
    match (element, f.len) {
        (Some(i), _) => set(rec, i, scalar(f.kind, raw.get())?),
        (None, None) => set(rec, 0, scalar(f.kind, raw.get())?),
        (None, Some(n)) => {
            for (i, item) in array(raw, n)?.into_iter().enumerate() {
                set(rec, i, scalar(f.kind, item.get())?);
            }
        }
    }
    Ok(())
}

/// One JSON value's text as a value of `kind`. Floats are parsed with Rust's exact
/// parser (serde_json's default may be one ulp off), so a log reads back bit for bit.
fn scalar(kind: Kind, text: &str) -> Result<Value, String> {
    let bad = |what: &str| format!("`{text}` is not {what}");
    let int = |what| text.parse::<u64>().map_err(|_| bad(what));
    match kind {
        Kind::F64 if text == "null" => Ok(Value::F64(f64::NAN)),
        Kind::F64 => text
            .parse::<f64>()
            .map(Value::F64)
            .map_err(|_| bad("a number")),
        Kind::Bool => match text {
            "true" => Ok(Value::Bool(true)),
            "false" => Ok(Value::Bool(false)),
            _ => Err(bad("true or false")),
        },
        Kind::U32 => {
            int("a 32-bit unsigned integer").and_then(|n| match n <= u64::from(u32::MAX) {
                true => Ok(Value::U64(n)),
                false => Err(bad("a 32-bit unsigned integer")),
            })
        }
        Kind::U64 => int("an unsigned integer").map(Value::U64),
        Kind::I64 => text
            .parse::<i64>()
            .map(Value::I64)
            .map_err(|_| bad("an integer")),
        Kind::Hex => serde_json::from_str::<String>(text)
            .ok()
            .and_then(|s| u64::from_str_radix(&s, 16).ok())
            .map(Value::U64)
            .ok_or_else(|| bad("a hex string")),
        Kind::OptU64 | Kind::OptI64 if text == "null" => Ok(Value::Absent),
        Kind::OptU64 => int("an unsigned integer or null").map(Value::U64),
        Kind::OptI64 => text
            .parse::<i64>()
            .map(Value::I64)
            .map_err(|_| bad("an integer or null")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::json_schema::validate;
    use oils_emulator::log_fields::Derived;

    fn distinct() -> Record {
        let mut r = Record::default();
        let mut x = 0.0;
        for f in FIELDS {
            if let Some(set) = f.setter() {
                for i in 0..f.count() {
                    x += 1.0;
                    let v = match f.kind {
                        Kind::F64 => Value::F64(x / 3.0),
                        Kind::Bool => Value::Bool(i % 2 == 0),
                        Kind::I64 | Kind::OptI64 => Value::I64(-(x as i64)),
                        _ => Value::U64(x as u64),
                    };
                    set(&mut r, i, v);
                }
            }
        }
        r
    }

    #[test]
    fn every_topic_reads_back_what_it_wrote_and_fits_its_schema() {
        let rec = distinct();
        let derived = Derived::default();
        let sample = Sample {
            record: &rec,
            derived: &derived,
        };
        let mut back = Record::default();
        for topic in Topic::ALL {
            let json = serde_json::to_vec(&message(topic, &sample)).unwrap();
            let value: serde_json::Value = serde_json::from_slice(&json).unwrap();
            validate(&schema(topic), &value).unwrap_or_else(|e| panic!("{topic:?}: {e}"));
            read_message(topic, &json, 2, &mut back).unwrap();
        }
        assert_eq!(back, rec);
    }

    #[test]
    fn a_message_keeps_the_shape_foxglove_layouts_name() {
        let rec = distinct();
        let derived = Derived::default();
        let sample = Sample {
            record: &rec,
            derived: &derived,
        };
        let tlm = serde_json::to_value(message(Topic::Telemetry, &sample)).unwrap();
        assert_eq!(tlm["header"]["step"], rec.telemetry.header.step);
        assert_eq!(
            tlm["header"]["run_id"],
            format!("{:016x}", rec.telemetry.header.run_id)
        );
        assert_eq!(tlm["nav"]["pos_mci_m"].as_array().unwrap().len(), 3);
        assert_eq!(
            tlm["propulsion"]["engines"][3]["thrust_n"],
            rec.telemetry.propulsion.engines[3].thrust_n
        );
        let cmd = serde_json::to_value(message(Topic::Command, &sample)).unwrap();
        assert_eq!(cmd["applied"]["on"][0], true);
    }

    #[test]
    fn a_missing_or_mistyped_field_is_named() {
        let rec = distinct();
        let derived = Derived::default();
        let sample = Sample {
            record: &rec,
            derived: &derived,
        };
        let mut v = serde_json::to_value(message(Topic::Truth, &sample)).unwrap();
        v.as_object_mut().unwrap().remove("faults_active");
        let json = serde_json::to_vec(&v).unwrap();
        let mut back = Record::default();
        // Format 1 files had no faults_active; format 2 files must.
        read_message(Topic::Truth, &json, 1, &mut back).unwrap();
        let e = read_message(Topic::Truth, &json, 2, &mut back).unwrap_err();
        assert!(e.contains("faults_active"), "{e}");
        v["mass_kg"] = "heavy".into();
        let e =
            read_message(Topic::Truth, &serde_json::to_vec(&v).unwrap(), 1, &mut back).unwrap_err();
        assert!(e.contains("mass_kg"), "{e}");
    }
}
