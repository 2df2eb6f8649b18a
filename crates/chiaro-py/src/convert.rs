//! Conversions between Python values and the serde form of chiaro's types.
//!
//! Scene items built from Python (materials, lights, the camera) are filled
//! in through their serde form: keyword arguments become a JSON object that
//! is laid over the item's default and deserialised, so every field the Rust
//! type has is reachable under its Rust name, unknown keys are errors that
//! list the known ones, and a plain number given for an RGB field (`[f32; 3]`
//! in the default) is broadcast to all three channels.

use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use serde_json::{Map, Value};

/// Converts a Python value (None, bool, int, float, str, list, tuple, dict
/// with str keys, or anything with `tolist()` such as a numpy array or
/// scalar) to JSON.
///
/// # Errors
/// `TypeError` for other types, non-finite floats, or non-string keys.
pub fn py_to_json(obj: &Bound<'_, PyAny>) -> PyResult<Value> {
    if obj.is_none() {
        return Ok(Value::Null);
    }
    if obj.is_instance_of::<PyBool>() {
        return Ok(Value::Bool(obj.extract::<bool>()?));
    }
    if obj.is_instance_of::<PyInt>() {
        if let Ok(i) = obj.extract::<i64>() {
            return Ok(Value::from(i));
        }
        return Ok(Value::from(obj.extract::<u64>()?));
    }
    if obj.is_instance_of::<PyFloat>() {
        let f = obj.extract::<f64>()?;
        return serde_json::Number::from_f64(f)
            .map(Value::Number)
            .ok_or_else(|| PyTypeError::new_err(format!("{f} is not a finite number")));
    }
    if let Ok(s) = obj.cast::<PyString>() {
        return Ok(Value::String(s.to_str()?.to_owned()));
    }
    if let Ok(d) = obj.cast::<PyDict>() {
        let mut map = Map::new();
        for (k, v) in d.iter() {
            let key: String = k
                .extract()
                .map_err(|_| PyTypeError::new_err("dictionary keys must be strings"))?;
            map.insert(key, py_to_json(&v)?);
        }
        return Ok(Value::Object(map));
    }
    // Lists and tuples are both JSON arrays.
    if obj.is_instance_of::<PyList>() || obj.is_instance_of::<PyTuple>() {
        return obj
            .try_iter()?
            .map(|v| py_to_json(&v?))
            .collect::<PyResult<_>>()
            .map(Value::Array);
    }
    if obj.hasattr("tolist")? {
        let plain = obj.call_method0("tolist")?;
        // A 0-d numpy value's tolist() is a Python scalar; guard against
        // objects whose tolist() returns themselves.
        if !plain.is(obj) {
            return py_to_json(&plain);
        }
    }
    Err(PyTypeError::new_err(format!(
        "cannot use a value of type {} here (expected a number, string, bool, list, dict or numpy array)",
        obj.get_type().name()?
    )))
}

/// Converts JSON to the corresponding Python value (dict, list, float, int,
/// str, bool, None).
pub fn json_to_py<'py>(py: Python<'py>, value: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match value {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Number(n) => {
            if let Some(i) = n.as_i64() {
                i.into_pyobject(py)?.into_any()
            } else if let Some(u) = n.as_u64() {
                u.into_pyobject(py)?.into_any()
            } else {
                n.as_f64().unwrap_or(0.0).into_pyobject(py)?.into_any()
            }
        }
        Value::String(s) => PyString::new(py, s).into_any(),
        Value::Array(a) => {
            let items = a
                .iter()
                .map(|v| json_to_py(py, v))
                .collect::<PyResult<Vec<_>>>()?;
            PyList::new(py, items)?.into_any()
        }
        Value::Object(m) => {
            let d = PyDict::new(py);
            for (k, v) in m {
                d.set_item(k, json_to_py(py, v)?)?;
            }
            d.into_any()
        }
    })
}

/// Lays `props` (a JSON object) over `default` (the serde form of a default
/// item): keys must exist in `default` (else the error lists the known
/// ones); a number given where the default holds a 3-element array is
/// broadcast (`0.5` → `[0.5, 0.5, 0.5]`); a nested object is merged
/// recursively when the default holds an object there.
///
/// # Errors
/// A message naming the unknown key and the known ones, or saying that
/// `props` is not an object.
pub fn merge_props(default: &Value, props: &Value, what: &str) -> Result<Value, String> {
    let (Value::Object(base), Value::Object(over)) = (default, props) else {
        return Err(format!("{what}: expected keyword arguments or a dict"));
    };
    let mut out = base.clone();
    for (k, v) in over {
        let Some(d) = base.get(k) else {
            let mut known: Vec<&str> = base.keys().map(String::as_str).collect();
            known.sort_unstable();
            return Err(format!(
                "{what}: unknown property `{k}` (known: {})",
                known.join(", ")
            ));
        };
        let merged = match (d, v) {
            (Value::Array(a), Value::Number(_)) if a.len() == 3 => {
                Value::Array(vec![v.clone(), v.clone(), v.clone()])
            }
            (Value::Object(_), Value::Object(_)) => merge_props(d, v, &format!("{what}.{k}"))?,
            _ => v.clone(),
        };
        out.insert(k.clone(), merged);
    }
    Ok(Value::Object(out))
}

/// Writes a JSON value as a TOML literal for `chiaro::settings::apply_override`
/// (`3`, `0.5`, `true`, `[0, 0, 1]`, `"map"`). JSON numbers, booleans,
/// arrays and strings are valid TOML literals; objects become inline tables.
pub fn toml_literal(value: &Value) -> String {
    match value {
        Value::Null => "\"\"".into(),
        Value::Object(m) => {
            let parts: Vec<String> = m
                .iter()
                .map(|(k, v)| format!("{} = {}", Value::String(k.clone()), toml_literal(v)))
                .collect();
            format!("{{ {} }}", parts.join(", "))
        }
        Value::Array(a) => {
            let parts: Vec<String> = a.iter().map(toml_literal).collect();
            format!("[{}]", parts.join(", "))
        }
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn merge_broadcasts_scalars_and_rejects_unknown_keys() {
        let default = json!({"diffuse": [0.8, 0.8, 0.8], "shininess": 20.0, "name": ""});
        let merged = merge_props(&default, &json!({"diffuse": 0.5, "name": "x"}), "material")
            .expect("known keys");
        assert_eq!(merged["diffuse"], json!([0.5, 0.5, 0.5]));
        assert_eq!(merged["shininess"], json!(20.0));
        assert_eq!(merged["name"], json!("x"));
        let err =
            merge_props(&default, &json!({"difuse": 0.5}), "material").expect_err("unknown key");
        assert!(
            err.contains("difuse") && err.contains("diffuse, name, shininess"),
            "{err}"
        );
    }

    #[test]
    fn merge_recurses_into_tables() {
        let default = json!({"a": {"b": 1, "c": 2}});
        let merged = merge_props(&default, &json!({"a": {"c": 5}}), "x").expect("known");
        assert_eq!(merged, json!({"a": {"b": 1, "c": 5}}));
        assert!(merge_props(&default, &json!({"a": {"d": 5}}), "x").is_err());
    }

    #[test]
    fn toml_literals_parse_back() {
        for (v, want) in [
            (json!(3), "3"),
            (json!(0.5), "0.5"),
            (json!(true), "true"),
            (json!([0, 0, 1]), "[0, 0, 1]"),
            (json!("map"), "\"map\""),
            (json!({"far": 2.0}), "{ \"far\" = 2.0 }"),
        ] {
            assert_eq!(toml_literal(&v), want);
        }
    }
}
