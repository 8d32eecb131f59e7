//! The keys a configuration must set (the user's columns, candidate gain and margin): their
//! placeholder in the printed template, the check that names every one left unset, and the
//! template with G5 node b's choices for the examples.

use super::DEFAULT_CONFIG;

/// [`DEFAULT_CONFIG`] with the required keys set for node b of the G5 benchmark as
/// `streamcert simulate g5` writes it (time `t`, output `y_b`, input `u_b`, the paper's gain
/// `K = [[-4.0]]` and margin 0.05): the configuration of the project's examples, tests and
/// benchmarks. Not a default: a user's plant needs its own.
#[must_use]
pub fn g5_node_b() -> String {
    DEFAULT_CONFIG
        .replacen("time = \"REQUIRED\"", "time = \"t\"", 1)
        .replacen("outputs = [\"REQUIRED\"]", "outputs = [\"y_b\"]", 1)
        .replacen("inputs = [\"REQUIRED\"]", "inputs = [\"u_b\"]", 1)
        .replacen("gain = \"REQUIRED\"", "gain = [[-4.0]]", 1)
        .replacen("margin = \"REQUIRED\"", "margin = 0.05", 1)
}

/// The value `--print-config` writes for each key the user must choose: a file that keeps it
/// (or omits the key) is refused, naming the key.
pub const REQUIRED_VALUE: &str = "REQUIRED";

/// The keys a configuration must set, `(section, key, what it is)`: they describe the user's
/// plant and controller, so none has a default.
pub const REQUIRED_KEYS: [(&str, &str, &str); 5] = [
    (
        "columns",
        "time",
        "the time column's header (seconds, strictly increasing), for example \"t\"",
    ),
    ("columns", "outputs", "the measured outputs' headers, for example [\"level\"]"),
    ("columns", "inputs", "the applied inputs' headers, for example [\"pump\"]"),
    (
        "controller",
        "gain",
        "the candidate gain K to certify, m rows of p values (u = K y), for example [[-1.5]]",
    ),
    ("certificate", "margin", "the rate (1/s) the loop must contract at, > 0, for example 0.05"),
];

/// The required keys that `table` leaves unset (absent, or [`REQUIRED_VALUE`] anywhere in
/// the value), as `section.key`, in [`REQUIRED_KEYS`]' order.
#[must_use]
pub fn unset_required(table: &toml::Table) -> Vec<String> {
    fn placeholder(v: &toml::Value) -> bool {
        match v {
            toml::Value::String(s) => s == REQUIRED_VALUE,
            toml::Value::Array(a) => a.iter().any(placeholder),
            _ => false,
        }
    }
    REQUIRED_KEYS
        .iter()
        .filter(|(section, key, _)| {
            table
                .get(*section)
                .and_then(toml::Value::as_table)
                .and_then(|t| t.get(*key))
                .is_none_or(placeholder)
        })
        .map(|(section, key, _)| format!("{section}.{key}"))
        .collect()
}

/// The refusal for unset required keys: each named with what it is.
pub(super) fn required_message(unset: &[String]) -> String {
    let lines: Vec<String> = REQUIRED_KEYS
        .iter()
        .filter(|(s, k, _)| unset.contains(&format!("{s}.{k}")))
        .map(|(s, k, what)| format!("  {s}.{k}: {what}"))
        .collect();
    format!(
        "required {} not set: {} (they describe your plant and controller, so none has a \
         default; `streamcert certify --print-config` marks them \"{REQUIRED_VALUE}\"):\n{}",
        if unset.len() == 1 { "key" } else { "keys" },
        unset.join(", "),
        lines.join("\n")
    )
}
