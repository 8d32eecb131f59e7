//! Configurations from a TOML text or from a JSON object (a Python dict or keyword
//! arguments), read by the command line's own parser.

use streamcert_cli::config::{self, Config, DEFAULT_CONFIG};
use streamcert_cli::network::{self, NetConfig};

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
/// 0.05}, ...}`) laid over the command line's defaults (`certify --print-config`): sections
/// merge key by key, any other value replaces the default. So an empty object is the
/// default configuration, with the calibrated certificate and its guards.
///
/// # Errors
/// [`Error::Config`] for a value TOML cannot hold (`null`) and for everything the command
/// line refuses, with its message.
pub fn from_json_over_defaults(json: &str) -> Result<ConfigText, Error> {
    let user = json_table(json)?;
    let mut table: toml::Table = toml::from_str(DEFAULT_CONFIG)
        .map_err(|e| Error::Config(format!("the default configuration: {e}")))?;
    merge(&mut table, user);
    let text = toml::to_string(&table).map_err(|e| Error::Config(e.to_string()))?;
    from_toml(&text, "configuration")
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
