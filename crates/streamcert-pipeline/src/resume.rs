//! What `certify` and `network` share for checkpoints: writing one atomically, and opening a
//! sealed one for `--resume` (the envelope, the checksum and the configuration are checked,
//! and a checkpoint written with another configuration is refused naming the settings that
//! differ).

use std::io::Write;
use std::path::Path;

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;
use streamcert_certificate::CertifyError;

use crate::CliError;

/// Settings named in a refusal at most.
const SHOWN: usize = 3;

/// The payload `P` of the sealed checkpoint `bytes` (either encoding) for the configuration
/// `now`, or why not.
/// Where the envelope and checksum are intact but the configuration fingerprint is not
/// `now`'s, the message names up to three settings whose values differ (dotted paths of the
/// serialised configuration, as `config_of` finds it in the payload).
///
/// # Errors
/// The refusal's message: not a checkpoint, another format version, damaged, corrupted,
/// another configuration (with its differences), or a payload that does not parse.
pub(crate) fn open<P, C>(bytes: &[u8], now: &C, config_of: impl Fn(&P) -> &C) -> Result<P, String>
where
    P: DeserializeOwned,
    C: Serialize,
{
    let sealed = match streamcert_certificate::unseal(bytes, Some(now)) {
        Ok(sealed) => sealed,
        Err(e) => {
            let message = inner(e);
            // Intact but for another configuration: say what differs.
            let Ok(sealed) = streamcert_certificate::unseal::<C>(bytes, None) else {
                return Err(message);
            };
            let then = sealed.decode::<P>().ok();
            let diff = then.map(|p| differences(config_of(&p), now)).unwrap_or_default();
            return Err(if diff.is_empty() { message } else { format!("{message}: {diff}") });
        }
    };
    sealed.decode().map_err(inner)
}

/// The message of a checkpoint error without the library's `checkpoint:` prefix (the command
/// line names the file first).
pub(crate) fn inner(e: CertifyError) -> String {
    match e {
        CertifyError::Checkpoint(m) => m,
        other => other.to_string(),
    }
}

/// Up to [`SHOWN`] settings whose values differ between `then` and `now`, as `path: value in
/// the checkpoint, value now`, `; `-separated, with the number of further ones; empty when
/// their serialisations agree.
pub(crate) fn differences<C: Serialize>(then: &C, now: &C) -> String {
    let (Ok(a), Ok(b)) = (serde_json::to_value(then), serde_json::to_value(now)) else {
        return String::new();
    };
    let mut found = Vec::new();
    walk("", &a, &b, &mut found);
    let mut text: Vec<String> = found
        .iter()
        .take(SHOWN)
        .map(|(path, x, y)| format!("{path}: {x} in the checkpoint, {y} now"))
        .collect();
    if found.len() > SHOWN {
        text.push(format!("and {} more", found.len() - SHOWN));
    }
    text.join("; ")
}

/// Collect the differing leaves of `a` and `b` under `path` (objects by key, in key order;
/// anything else compared whole).
fn walk(path: &str, a: &Value, b: &Value, found: &mut Vec<(String, Value, Value)>) {
    match (a, b) {
        (Value::Object(x), Value::Object(y)) => {
            let mut keys: Vec<&String> = x.keys().chain(y.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                let sub = if path.is_empty() { k.clone() } else { format!("{path}.{k}") };
                let (u, v) = (x.get(k).unwrap_or(&Value::Null), y.get(k).unwrap_or(&Value::Null));
                walk(&sub, u, v, found);
            }
        }
        _ if a != b => found.push((path.to_string(), a.clone(), b.clone())),
        _ => {}
    }
}

/// Write `bytes` to `path` atomically: a unique temporary file beside the target, flushed to
/// disk, then renamed over it, so a crash leaves either the old file or the new one, never a
/// torn one.
///
/// # Errors
/// [`CliError::Io`] naming the checkpoint.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<(), CliError> {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let name = path.file_name().map_or_else(|| "checkpoint".into(), |n| n.to_string_lossy());
    let tmp = path.with_file_name(format!(".{name}.{}.{nanos}.tmp", std::process::id()));
    let write = || -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)?;
        // Make the rename itself durable where the platform allows opening a directory.
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty())
            && let Ok(d) = std::fs::File::open(dir)
        {
            let _ = d.sync_all();
        }
        Ok(())
    };
    write().map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        CliError::io(format!("writing the checkpoint {}", path.display()), e)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use streamcert_certificate::Encoding;

    #[derive(Serialize, serde::Deserialize, PartialEq, Debug)]
    struct Inner {
        margin: f64,
        window: usize,
    }

    #[derive(Serialize, serde::Deserialize, PartialEq, Debug)]
    struct Payload {
        config: Inner,
        rows: u64,
    }

    /// Oracle: the two configurations' own fields. The differences name exactly the changed
    /// settings, a checkpoint of the same configuration opens, and a damaged one is refused
    /// without a list.
    #[test]
    fn a_checkpoint_of_another_configuration_names_what_differs() {
        let then = Inner { margin: 0.05, window: 150 };
        let p = Payload { config: Inner { margin: 0.05, window: 150 }, rows: 7 };
        let text = streamcert_certificate::seal_value(&p, Encoding::Json, &then).expect("sealed");
        let text = String::from_utf8(text).expect("JSON is text");
        let opened: Payload = open(text.as_bytes(), &then, |p: &Payload| &p.config).expect("opens");
        let binary = streamcert_certificate::seal_value(&p, Encoding::Binary, &then).unwrap();
        let opened_binary: Payload = open(&binary, &then, |p: &Payload| &p.config).unwrap();
        assert_eq!(opened_binary, p);
        assert_eq!(opened, p);
        let now = Inner { margin: 0.1, window: 150 };
        let err = open(text.as_bytes(), &now, |p: &Payload| &p.config).unwrap_err();
        assert_eq!(
            err,
            "the checkpoint was written with a different configuration: \
             margin: 0.05 in the checkpoint, 0.1 now"
        );
        let both = Inner { margin: 0.1, window: 300 };
        let err = open(text.as_bytes(), &both, |p: &Payload| &p.config).unwrap_err();
        assert!(
            err.ends_with(
                "margin: 0.05 in the checkpoint, 0.1 now; window: 150 in the checkpoint, 300 now"
            ),
            "{err}"
        );
        let damaged = text.replace("\"rows\":7", "\"rows\":8");
        let err = open(damaged.as_bytes(), &now, |p: &Payload| &p.config).unwrap_err();
        assert!(err.starts_with("the checkpoint is corrupted"), "{err}");
        assert!(!err.contains("margin"), "{err}");
    }

    #[test]
    fn many_differences_are_counted_beyond_three() {
        let a = serde_json::json!({"a": 1, "b": {"c": 2, "d": 3}, "e": [1, 2], "f": 4});
        let b = serde_json::json!({"a": 2, "b": {"c": 3, "d": 4}, "e": [1, 3], "f": 4});
        assert_eq!(
            differences(&a, &b),
            "a: 1 in the checkpoint, 2 now; b.c: 2 in the checkpoint, 3 now; \
             b.d: 3 in the checkpoint, 4 now; and 1 more"
        );
        assert_eq!(differences(&a, &a), "");
    }
}
