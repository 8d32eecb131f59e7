//! The crate graph: the command line's crate is a leaf. The pipeline it runs lives in
//! `streamcert-pipeline`, which the Python package and `xtask` call directly, so no crate
//! depends on `streamcert-cli` (and a user's program never needs the binary's crate).

use std::path::Path;

/// Every `Cargo.toml` of the workspace: the root, `crates/*` and `xtask`.
fn manifests() -> Vec<std::path::PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut out = vec![root.join("Cargo.toml"), root.join("xtask/Cargo.toml")];
    for entry in std::fs::read_dir(root.join("crates")).expect("crates/") {
        let path = entry.expect("entry").path().join("Cargo.toml");
        if path.exists() {
            out.push(path);
        }
    }
    out
}

#[test]
fn no_crate_depends_on_the_command_line_crate() {
    let found = manifests();
    assert!(found.len() >= 13, "the workspace's manifests: {found:?}");
    let mut pipeline_users = 0;
    for path in found {
        let text = std::fs::read_to_string(&path).expect("manifest");
        let manifest: toml::Table = toml::from_str(&text).expect("a TOML manifest");
        let name = manifest
            .get("package")
            .and_then(|p| p.get("name"))
            .and_then(toml::Value::as_str)
            .unwrap_or("(workspace)");
        for section in ["dependencies", "dev-dependencies", "build-dependencies"] {
            if let Some(deps) = manifest.get(section).and_then(toml::Value::as_table) {
                assert!(
                    !deps.contains_key("streamcert-cli"),
                    "{name} ({}) lists streamcert-cli in [{section}]",
                    path.display()
                );
                pipeline_users += usize::from(deps.contains_key("streamcert-pipeline"));
            }
        }
    }
    // The command line, the Python package, xtask and the root's benchmarks call the pipeline.
    assert!(pipeline_users >= 4, "{pipeline_users} crates use streamcert-pipeline");
}

/// Only the command line (and the root's benchmarks) link the live sources' MQTT client and
/// the operators' web server: the pipeline and the Python package read files, so a
/// downstream user of either links neither.
#[test]
fn only_the_command_line_links_the_live_sources() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for krate in ["streamcert-pipeline", "streamcert-python", "streamcert-certificate"] {
        let text = std::fs::read_to_string(root.join("crates").join(krate).join("Cargo.toml"))
            .expect("manifest");
        let manifest: toml::Table = toml::from_str(&text).expect("a TOML manifest");
        let deps = manifest.get("dependencies").and_then(toml::Value::as_table).expect("deps");
        for client in [
            "streamcert-live",
            "rumqttc",
            "rumqttd",
            "streamcert-serve",
            "axum",
            "prometheus-client",
        ] {
            assert!(!deps.contains_key(client), "{krate} links {client}");
        }
    }
    let cli = std::fs::read_to_string(root.join("crates/streamcert-cli/Cargo.toml")).expect("cli");
    assert!(cli.contains("streamcert-live"), "the command line reads live sources");
}
