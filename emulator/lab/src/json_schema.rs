//! A validator for the subset of JSON Schema the MCAP log's schemas use: `type` (one
//! name or a list), `properties`, `required`, `additionalProperties: false`, `items`
//! (one schema for every element), `minItems`, `maxItems`; `title` is ignored. Any
//! other keyword is refused, so a schema cannot silently say more than is checked.
//! (A maintained validator crate would pull in regex and HTTP dependencies for the few
//! keywords used here.)

use serde_json::Value;

/// Checks `instance` against `schema`; the error names the first path that fails.
pub fn validate(schema: &Value, instance: &Value) -> Result<(), String> {
    check(schema, instance, "$")
}

fn check(schema: &Value, v: &Value, at: &str) -> Result<(), String> {
    let s = schema
        .as_object()
        .ok_or_else(|| format!("{at}: the schema is not an object"))?;
    for key in s.keys() {
        if ![
            "title",
            "type",
            "properties",
            "required",
            "additionalProperties",
            "items",
            "minItems",
            "maxItems",
        ]
        .contains(&key.as_str())
        {
            return Err(format!("{at}: schema keyword `{key}` is not supported"));
        }
    }
    if let Some(t) = s.get("type") {
        let names: Vec<&str> = match t {
            Value::String(n) => vec![n.as_str()],
            Value::Array(ns) => ns.iter().filter_map(Value::as_str).collect(),
            _ => return Err(format!("{at}: bad `type` in the schema")),
        };
        if !names.iter().any(|n| is_type(n, v)) {
            return Err(format!("{at}: {v} is not of type {}", names.join(" or ")));
        }
    }
    if let Value::Object(map) = v {
        let props = s.get("properties").and_then(Value::as_object);
        if let Some(required) = s.get("required").and_then(Value::as_array) {
            for name in required.iter().filter_map(Value::as_str) {
                if !map.contains_key(name) {
                    return Err(format!("{at}: required property `{name}` is missing"));
                }
            }
        }
        for (name, value) in map {
            let path = format!("{at}.{name}");
            match props.and_then(|p| p.get(name)) {
                Some(sub) => check(sub, value, &path)?,
                None if s.get("additionalProperties") == Some(&Value::Bool(false)) => {
                    return Err(format!("{path}: not in the schema"));
                }
                None => {}
            }
        }
    }
    if let Value::Array(items) = v {
        let n = items.len() as u64;
        if let Some(min) = s.get("minItems").and_then(Value::as_u64) {
            if n < min {
                return Err(format!("{at}: {n} elements, fewer than {min}"));
            }
        }
        if let Some(max) = s.get("maxItems").and_then(Value::as_u64) {
            if n > max {
                return Err(format!("{at}: {n} elements, more than {max}"));
            }
        }
        if let Some(sub) = s.get("items") {
            for (i, item) in items.iter().enumerate() {
                check(sub, item, &format!("{at}[{i}]"))?;
            }
        }
    }
    Ok(())
}

fn is_type(name: &str, v: &Value) -> bool {
    match name {
        "null" => v.is_null(),
        "boolean" => v.is_boolean(),
        "object" => v.is_object(),
        "array" => v.is_array(),
        "string" => v.is_string(),
        "number" => v.is_number(),
        "integer" => v.is_u64() || v.is_i64(),
        _ => false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn schema() -> Value {
        json!({
            "title": "t",
            "type": "object",
            "properties": {
                "a": {"type": ["number", "null"]},
                "v": {"type": "array", "items": {"type": "integer"}, "minItems": 2, "maxItems": 2},
            },
            "required": ["a", "v"],
            "additionalProperties": false,
        })
    }

    #[test]
    fn accepts_what_the_schema_says() {
        validate(&schema(), &json!({"a": 1.5, "v": [1, 2]})).unwrap();
        validate(&schema(), &json!({"a": null, "v": [0, 7]})).unwrap();
    }

    #[test]
    fn refuses_an_extra_a_missing_or_a_mistyped_field() {
        let e = validate(&schema(), &json!({"a": 1, "v": [1, 2], "b": 0})).unwrap_err();
        assert!(e.contains("$.b"), "{e}");
        let e = validate(&schema(), &json!({"v": [1, 2]})).unwrap_err();
        assert!(e.contains("`a`"), "{e}");
        let e = validate(&schema(), &json!({"a": "x", "v": [1, 2]})).unwrap_err();
        assert!(e.contains("$.a"), "{e}");
        let e = validate(&schema(), &json!({"a": 1, "v": [1, 2.5]})).unwrap_err();
        assert!(e.contains("$.v[1]"), "{e}");
        let e = validate(&schema(), &json!({"a": 1, "v": [1]})).unwrap_err();
        assert!(e.contains("fewer"), "{e}");
    }

    #[test]
    fn refuses_keywords_it_does_not_check() {
        let e = validate(&json!({"pattern": "^a"}), &json!("a")).unwrap_err();
        assert!(e.contains("pattern"), "{e}");
    }
}
