//! Message payloads into samples: a whole row per message (a JSON object with named fields,
//! or a CSV line), or one signal per message (a number, or a JSON object with a value and a
//! source timestamp). Every way a payload can fail to be a number the certifier may see is a
//! [`PayloadError`] of a named kind, with an excerpt of the payload.

use serde::Deserialize;
use streamcert_pipeline::input::Sample;

/// The largest payload accepted, bytes, unless configured (`max_payload`): a row of a few
/// dozen numbers is well under it.
pub const DEFAULT_MAX_PAYLOAD: usize = 64 * 1024;

/// The longest excerpt of a bad payload quoted in a report, characters.
const EXCERPT: usize = 60;

/// A payload that is not a sample.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{kind}: {message}")]
pub struct PayloadError {
    /// The kind, one of [`PayloadError::KINDS`].
    pub kind: &'static str,
    /// What was found and what was expected, with an excerpt of the payload.
    pub message: String,
}

impl PayloadError {
    /// Every kind of bad payload, as counted in the summary.
    pub const KINDS: [&'static str; 8] = [
        "oversized",
        "not_utf8",
        "not_json",
        "missing_field",
        "not_a_number",
        "not_finite",
        "wrong_field_count",
        "time_backwards",
    ];

    /// A bad payload of `kind`, quoting `payload`.
    #[must_use]
    pub fn new(kind: &'static str, what: &str, payload: &[u8]) -> Self {
        Self { kind, message: format!("{what} (payload `{}`)", excerpt(payload)) }
    }
}

/// At most 60 characters of `payload`, lossy UTF-8, control characters escaped.
#[must_use]
pub fn excerpt(payload: &[u8]) -> String {
    let text = String::from_utf8_lossy(&payload[..payload.len().min(4 * EXCERPT)]);
    let mut out: String = text.chars().take(EXCERPT).flat_map(char::escape_debug).collect();
    if text.chars().count() > EXCERPT || payload.len() > 4 * EXCERPT {
        out.push('…');
    }
    out
}

/// How a whole-row message is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum RowFormat {
    /// A JSON object whose keys name the time and every configured column:
    /// `{"t": 1.5, "y_b": 0.12, "u_b": -0.4}`.
    Json,
    /// A CSV line whose fields are the columns of `csv_columns`, in that order.
    Csv,
}

/// How a one-signal message is written.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SignalFormat {
    /// A JSON object with the value and its source timestamp: `{"t": 1.5, "value": 0.12}`.
    Json,
    /// A bare number; its time is the arrival time (only with `time = "arrival"`).
    Value,
}

/// A finite number from a JSON value, or the error naming `field`.
fn number(v: Option<&serde_json::Value>, field: &str, payload: &[u8]) -> Result<f64, PayloadError> {
    let v = v.ok_or_else(|| {
        PayloadError::new("missing_field", &format!("no field `{field}`"), payload)
    })?;
    let x = v.as_f64().ok_or_else(|| {
        PayloadError::new("not_a_number", &format!("field `{field}` is {v}, not a number"), payload)
    })?;
    finite(x, field, payload)
}

fn finite(x: f64, field: &str, payload: &[u8]) -> Result<f64, PayloadError> {
    if x.is_finite() {
        Ok(x)
    } else {
        Err(PayloadError::new("not_finite", &format!("field `{field}` is {x}"), payload))
    }
}

/// The payload as UTF-8 within `max` bytes.
fn text(payload: &[u8], max: usize) -> Result<&str, PayloadError> {
    if payload.len() > max {
        let what = format!("{} bytes, above the limit of {max}", payload.len());
        return Err(PayloadError::new("oversized", &what, payload));
    }
    std::str::from_utf8(payload)
        .map_err(|_| PayloadError::new("not_utf8", "not valid UTF-8", payload))
}

/// A JSON object.
fn object(
    payload: &[u8],
    max: usize,
) -> Result<serde_json::Map<String, serde_json::Value>, PayloadError> {
    let text = text(payload, max)?;
    match serde_json::from_str::<serde_json::Value>(text) {
        Ok(serde_json::Value::Object(map)) => Ok(map),
        Ok(other) => Err(PayloadError::new(
            "not_json",
            &format!("a JSON {}, not an object", kind_of(&other)),
            payload,
        )),
        Err(e) => Err(PayloadError::new("not_json", &format!("not JSON: {e}"), payload)),
    }
}

fn kind_of(v: &serde_json::Value) -> &'static str {
    match v {
        serde_json::Value::Null => "null",
        serde_json::Value::Bool(_) => "boolean",
        serde_json::Value::Number(_) => "number",
        serde_json::Value::String(_) => "string",
        serde_json::Value::Array(_) => "array",
        serde_json::Value::Object(_) => "object",
    }
}

/// The names a row message carries: the time, the outputs and the inputs (as in `[columns]`).
#[derive(Debug, Clone)]
pub struct RowFields {
    /// The time's field.
    pub time: String,
    /// The outputs' fields.
    pub outputs: Vec<String>,
    /// The inputs' fields.
    pub inputs: Vec<String>,
    /// For [`RowFormat::Csv`], the line's fields in order (the three above among them).
    pub csv_columns: Vec<String>,
}

/// Parse a whole-row message into `s` (`t`, `y`, `u`; `line` untouched).
///
/// # Errors
/// Every kind of [`PayloadError`] but `time_backwards` (the source checks the order).
pub fn parse_row(
    payload: &[u8],
    format: RowFormat,
    fields: &RowFields,
    max: usize,
    s: &mut Sample,
) -> Result<(), PayloadError> {
    match format {
        RowFormat::Json => {
            let map = object(payload, max)?;
            let t = number(map.get(&fields.time), &fields.time, payload)?;
            s.y.clear();
            for name in &fields.outputs {
                s.y.push(number(map.get(name), name, payload)?);
            }
            s.u.clear();
            for name in &fields.inputs {
                s.u.push(number(map.get(name), name, payload)?);
            }
            s.t = t;
        }
        RowFormat::Csv => {
            let line = text(payload, max)?.trim_end_matches(['\r', '\n']);
            let values: Vec<&str> = line.split(',').map(str::trim).collect();
            if values.len() != fields.csv_columns.len() {
                let what = format!(
                    "{} fields, expected {} ({})",
                    values.len(),
                    fields.csv_columns.len(),
                    fields.csv_columns.join(",")
                );
                return Err(PayloadError::new("wrong_field_count", &what, payload));
            }
            let field = |name: &str| -> Result<f64, PayloadError> {
                let i = fields.csv_columns.iter().position(|c| c == name).unwrap_or(usize::MAX);
                let raw = values.get(i).copied().unwrap_or_default();
                let x: f64 = fast_float2::parse(raw).map_err(|_| {
                    let what = format!("field `{name}` is `{raw}`, not a number");
                    PayloadError::new("not_a_number", &what, payload)
                })?;
                finite(x, name, payload)
            };
            let t = field(&fields.time)?;
            s.y.clear();
            for name in &fields.outputs {
                s.y.push(field(name)?);
            }
            s.u.clear();
            for name in &fields.inputs {
                s.u.push(field(name)?);
            }
            s.t = t;
        }
    }
    Ok(())
}

/// Parse a one-signal message: `(source time, value)`; `arrival` is the time to use for a
/// [`SignalFormat::Value`] payload.
///
/// # Errors
/// Every kind of [`PayloadError`] but `wrong_field_count` and `time_backwards`.
pub fn parse_signal(
    payload: &[u8],
    format: SignalFormat,
    keys: (&str, &str),
    arrival: f64,
    max: usize,
) -> Result<(f64, f64), PayloadError> {
    let (time_key, value_key) = keys;
    match format {
        SignalFormat::Json => {
            let map = object(payload, max)?;
            let t = number(map.get(time_key), time_key, payload)?;
            let v = number(map.get(value_key), value_key, payload)?;
            Ok((t, v))
        }
        SignalFormat::Value => {
            let raw = text(payload, max)?.trim();
            let v: f64 = fast_float2::parse(raw).map_err(|_| {
                PayloadError::new("not_a_number", &format!("`{raw}` is not a number"), payload)
            })?;
            Ok((arrival, finite(v, "value", payload)?))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fields() -> RowFields {
        RowFields {
            time: "t".into(),
            outputs: vec!["y".into()],
            inputs: vec!["u".into()],
            csv_columns: vec!["t".into(), "y".into(), "u".into()],
        }
    }

    fn row(p: &str, f: RowFormat) -> Result<Sample, PayloadError> {
        let mut s = Sample::default();
        parse_row(p.as_bytes(), f, &fields(), 64, &mut s).map(|()| s)
    }

    #[test]
    fn every_kind_of_bad_row_is_named() {
        use RowFormat::{Csv, Json};
        let cases = [
            (
                r#"{"t":1,"y":2,"u":3,"pad":"xxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxxx"}"#,
                Json,
                "oversized",
            ),
            ("{\"t\":1,\"y\":\u{7f}", Json, "not_json"),
            ("[1,2,3]", Json, "not_json"),
            (r#"{"t":1,"y":2}"#, Json, "missing_field"),
            (r#"{"t":1,"y":"2","u":3}"#, Json, "not_a_number"),
            (r#"{"t":1,"y":null,"u":3}"#, Json, "not_a_number"),
            (r#"{"t":1,"y":1e999,"u":3}"#, Json, "not_json"),
            ("1,2", Csv, "wrong_field_count"),
            ("1,x,3", Csv, "not_a_number"),
            ("1,NaN,3", Csv, "not_finite"),
            ("1,inf,3", Csv, "not_finite"),
        ];
        for (payload, format, kind) in cases {
            let e = row(payload, format).expect_err(payload);
            assert_eq!(e.kind, kind, "{payload}: {e}");
            assert!(PayloadError::KINDS.contains(&e.kind));
        }
        let mut s = Sample::default();
        let e = parse_row(&[0xff, 0xfe], RowFormat::Csv, &fields(), 64, &mut s).unwrap_err();
        assert_eq!(e.kind, "not_utf8");
    }

    #[test]
    fn good_rows_parse_to_the_same_bits_as_the_csv_reader() {
        let j = row(r#"{"u":-0.4,"t":0.02,"y":0.1234567890123456789}"#, RowFormat::Json).unwrap();
        let c = row("0.02,0.1234567890123456789,-0.4\n", RowFormat::Csv).unwrap();
        assert_eq!(j, c);
        assert_eq!(j.y[0].to_bits(), 0.123_456_789_012_345_68_f64.to_bits());
    }

    #[test]
    fn signals_parse_and_fail_by_kind() {
        let keys = ("ts", "value");
        let ok = parse_signal(br#"{"ts": 3.5, "value": -1}"#, SignalFormat::Json, keys, 0.0, 64);
        assert_eq!(ok, Ok((3.5, -1.0)));
        assert_eq!(parse_signal(b" 2.5\n", SignalFormat::Value, keys, 9.0, 64), Ok((9.0, 2.5)));
        let kind = |p: &[u8], f| parse_signal(p, f, keys, 0.0, 64).unwrap_err().kind;
        assert_eq!(kind(b"abc", SignalFormat::Value), "not_a_number");
        assert_eq!(kind(b"nan", SignalFormat::Value), "not_finite");
        assert_eq!(kind(br#"{"value": 1}"#, SignalFormat::Json), "missing_field");
        assert_eq!(kind(&[b'1'; 65], SignalFormat::Value), "oversized");
    }

    #[test]
    fn excerpts_are_short_and_escaped() {
        assert_eq!(excerpt(b"a\nb"), "a\\nb");
        let long = excerpt(&[b'x'; 1000]);
        assert_eq!(long.chars().count(), EXCERPT + 1);
    }
}
