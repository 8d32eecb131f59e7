//! Configurations from a TOML text or from a JSON object (a Python dict or keyword
//! arguments), read by the command line's own parser.

use streamcert_pipeline::config::{self, Config, DEFAULT_CONFIG, ErrorPlace};
use streamcert_pipeline::network::{self, NetConfig};

use crate::Error;

/// A `certify` configuration and the TOML text it was read from.
#[derive(Debug, Clone)]
pub struct ConfigText {
    /// The validated configuration.
    pub config: Config,
    /// The whole TOML text the command line would read to get the same configuration.
    pub text: String,
}

/// Read a `certify` configuration file's text exactly as `streamcert certify --config`
/// does; `name` names it in errors.
///
/// # Errors
/// [`Error::Config`] with the command line's message.
pub fn from_toml(text: &str, name: &str) -> Result<ConfigText, Error> {
    let config = config::parse(text, name)?;
    Ok(ConfigText { config, text: text.to_string() })
}

/// A `certify` configuration from a JSON object of sections (`{"calibration": {"delta":
/// 0.05}, ...}`) laid over the command line's template (`certify --print-config`): sections
/// merge key by key, any other value replaces the template's. The required keys (the
/// columns, the gain, the margin) must be given: an empty object is refused naming them.
///
/// # Errors
/// [`Error::Config`] for a value TOML cannot hold (`null`) and for everything the command
/// line refuses, with its message.
pub fn from_json_over_defaults(json: &str) -> Result<ConfigText, Error> {
    let user = json_table(json)?;
    let mut table: toml::Table = toml::from_str(DEFAULT_CONFIG)
        .map_err(|e| Error::Config(format!("the default configuration: {e}")))?;
    merge(&mut table, user);
    from_table(&table)
}

/// A configuration from a table built from the caller's mapping: errors name key paths.
fn from_table(table: &toml::Table) -> Result<ConfigText, Error> {
    let text = toml::to_string(table).map_err(|e| Error::Config(e.to_string()))?;
    let config = config::parse_placed(&text, "configuration", ErrorPlace::KeyPaths)?;
    Ok(ConfigText { config, text })
}

/// `cfg` with its `[columns]` names replaced where given (`None` keeps a name): the names
/// the verdict, the region columns and a checkpoint use, for arrays that carry their own
/// (a pandas Series' name).
///
/// # Errors
/// [`Error::Config`] as the command line refuses the renamed file (a name given twice, a
/// count that does not match the gain's shape).
pub fn with_columns(
    cfg: &ConfigText,
    time: Option<String>,
    outputs: Option<Vec<String>>,
    inputs: Option<Vec<String>>,
) -> Result<ConfigText, Error> {
    let mut table: toml::Table =
        toml::from_str(&cfg.text).map_err(|e| Error::Config(e.to_string()))?;
    let columns = table
        .entry("columns")
        .or_insert_with(|| toml::Value::Table(toml::Table::new()))
        .as_table_mut()
        .ok_or_else(|| Error::Config("[columns] is not a section".into()))?;
    let list = |names: Vec<String>| {
        toml::Value::Array(names.into_iter().map(toml::Value::String).collect())
    };
    if let Some(t) = time {
        columns.insert("time".into(), toml::Value::String(t));
    }
    if let Some(o) = outputs {
        columns.insert("outputs".into(), list(o));
    }
    if let Some(i) = inputs {
        columns.insert("inputs".into(), list(i));
    }
    from_table(&table)
}

/// A `network` configuration from its TOML text, exactly as `streamcert network --config`
/// reads it.
///
/// # Errors
/// [`Error::Config`] with the command line's message.
pub fn network_from_toml(text: &str, name: &str) -> Result<NetConfig, Error> {
    Ok(network::parse(text, name)?)
}

/// A `network` configuration from a JSON object with the TOML file's keys.
///
/// # Errors
/// As [`network_from_toml`].
pub fn network_from_json(json: &str) -> Result<(NetConfig, String), Error> {
    let table = json_table(json)?;
    let text = toml::to_string(&table).map_err(|e| Error::Config(e.to_string()))?;
    Ok((network_from_toml(&text, "configuration")?, text))
}

fn json_table(json: &str) -> Result<toml::Table, Error> {
    let v: serde_json::Value =
        serde_json::from_str(json).map_err(|e| Error::Config(format!("configuration: {e}")))?;
    match to_toml(&v, "configuration")? {
        toml::Value::Table(t) => Ok(t),
        _ => Err(Error::Config("configuration: expected a mapping of sections".into())),
    }
}

/// Sections (tables) merge key by key; anything else replaces.
fn merge(base: &mut toml::Table, over: toml::Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(toml::Value::Table(b)), toml::Value::Table(o)) => merge(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

fn to_toml(v: &serde_json::Value, at: &str) -> Result<toml::Value, Error> {
    use serde_json::Value as J;
    Ok(match v {
        J::Null => {
            return Err(Error::Config(format!(
                "{at}: None has no TOML form (leave the key out for its default)"
            )));
        }
        J::Bool(b) => toml::Value::Boolean(*b),
        J::Number(n) => match n.as_i64() {
            Some(i) => toml::Value::Integer(i),
            None => toml::Value::Float(n.as_f64().unwrap_or(f64::NAN)),
        },
        J::String(s) => toml::Value::String(s.clone()),
        J::Array(a) => toml::Value::Array(
            a.iter()
                .enumerate()
                .map(|(i, x)| to_toml(x, &format!("{at}[{i}]")))
                .collect::<Result<_, _>>()?,
        ),
        J::Object(o) => toml::Value::Table(
            o.iter()
                .map(|(k, x)| Ok((k.clone(), to_toml(x, &format!("{at}.{k}"))?)))
                .collect::<Result<_, Error>>()?,
        ),
    })
}
