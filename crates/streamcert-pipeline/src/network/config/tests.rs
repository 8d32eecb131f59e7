//! The network configuration: the example, the template, refusals, coupling files.

use super::*;

fn refused(text: &str, needle: &str) {
    match parse(text, "net.toml") {
        Err(e @ CliError::Config { .. }) => {
            let message = e.to_string();
            assert!(message.contains(needle), "`{needle}` not in: {message}");
        }
        other => panic!("expected a configuration error with `{needle}`, got {other:?}"),
    }
}

/// The committed example the docs run is [`EXAMPLE_CONFIG`], byte for byte.
#[test]
fn the_committed_example_is_the_example() {
    let committed = include_str!("../../../../../examples/data/g5_network.toml");
    assert_eq!(committed, EXAMPLE_CONFIG);
}

/// `network --print-config`'s template is refused naming every choice it leaves to the
/// user, and the example (the template with G5's choices) parses.
#[test]
fn the_template_names_every_required_key() {
    let err = parse(&template(), "net.toml").unwrap_err().to_string();
    for path in [
        "network.margin",
        "columns.time",
        "subsystem[0].outputs",
        "subsystem[0].inputs",
        "subsystem[0].gain",
        "subsystem[1].gain",
        "certificate.margin",
    ] {
        assert!(err.contains(path), "`{path}` not in: {err}");
    }
    assert!(!err.contains("gamma") && !err.contains("epoch"), "{err}");
    let one = EXAMPLE_CONFIG.replace("gain = [[-3.0]]", "gain = \"REQUIRED\"");
    let err = parse(&one, "net.toml").unwrap_err().to_string();
    assert!(err.contains("required key not set: subsystem[1].gain"), "{err}");
}

#[test]
fn the_example_parses_and_bad_networks_are_refused() {
    let cfg = parse(EXAMPLE_CONFIG, "example").expect("the example is valid");
    assert_eq!(cfg.dims, vec![(1, 1), (1, 1)]);
    assert_eq!(cfg.columns.outputs, ["y_a", "y_b"]);
    assert_eq!(cfg.network.couplings, vec![(0, 1, 0.4), (1, 0, 0.4)]);
    refused(&EXAMPLE_CONFIG.replace("from = \"B\"", "from = \"C\""), "`C`");
    refused(&EXAMPLE_CONFIG.replace("risk = 0.01 ", "risk = 1.5 "), "risk");
    refused(
        &EXAMPLE_CONFIG.replace("[ambiguity]", "[calibration]\nenabled = false\n\n[ambiguity]"),
        "no calibration",
    );
    // The default is the calibrated certificate at risk 0.01, δ/N per subsystem.
    assert_eq!(cfg.network.certificate, CertificateKind::Calibrated);
    for s in &cfg.network.subsystems {
        assert_eq!(s.certifier.calibration.map(|c| c.delta), Some(0.005));
    }
    let paper = EXAMPLE_CONFIG
        .replace("certificate = \"calibrated\"", "certificate = \"gaussian\"")
        .replace("risk = 0.01 ", "# risk = 0.01 ");
    let cfg = parse(&paper, "paper").expect("the paper-only mode is valid");
    assert_eq!(cfg.network.certificate, CertificateKind::Gaussian);
    refused(&EXAMPLE_CONFIG.replace("gamma = 0.4", "gamma = -0.4"), "γ must be finite and >= 0");
    refused(&EXAMPLE_CONFIG.replace("gain = [[-3.0]]", "gain = [[-3.0, 1.0]]"), "subsystem `B`");
    refused(&EXAMPLE_CONFIG.replace("epoch = 0.5", "epoch = 0.0"), "epoch");
    // Estimated couplings: one of gamma and estimate, and a run-level risk.
    refused(&paper.replace("gamma = 0.4", "estimate = true"), "[network] risk");
    refused(&EXAMPLE_CONFIG.replace("gamma = 0.4", "gamma = 0.4\nestimate = true"), "not both");
    refused(&EXAMPLE_CONFIG.replace("gamma = 0.4", ""), "needs `gamma`");
    let text = EXAMPLE_CONFIG
        .replacen("gamma = 0.4", "estimate = true", 1)
        .replace("risk = 0.01 ", "risk = 0.03 ");
    let cfg = parse(&text, "estimated").expect("valid");
    // B -> A estimated: A's inputs gain B's output, a zero gain row and one block.
    assert_eq!(cfg.dims, vec![(1, 2), (1, 1)]);
    assert_eq!(cfg.columns.inputs, ["u_a", "y_b", "u_b"]);
    let a = &cfg.network.subsystems[0].certifier;
    assert_eq!(a.gain, vec![-2.5, 0.0]);
    let blocks = a.couplings.as_ref().map(|c| (c.blocks.clone(), c.delta));
    assert_eq!(blocks, Some((vec![CouplingBlock { first: 1, len: 1 }], 0.01)));
    assert_eq!(cfg.network.estimated, vec![EstimatedCoupling { to: 0, from: 1, block: 0 }]);
    assert_eq!(cfg.network.couplings, vec![(1, 0, 0.4)]);
    // A run-level risk with the paper's certificate named: the named certificate composes
    // (the explicit paper-only choice, labelled as such), and the calibrations beside it
    // run at their share.
    let text = paper.replace("# risk = 0.01 ", "risk = 0.02 ");
    let cfg = parse(&text, "risk").expect("valid");
    assert_eq!(cfg.network.certificate, CertificateKind::Gaussian);
    for s in &cfg.network.subsystems {
        assert_eq!(s.certifier.calibration.map(|c| c.delta), Some(0.01));
    }
    assert_eq!(cfg.network.total_risk(), None, "the paper-only verdict states no risk");
}

#[test]
fn coupling_bounds_from_a_gains_file_in_either_layout() {
    let dir = std::env::temp_dir().join(format!("streamcert-gains-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("dir");
    let cfg_path = dir.join("net.toml");
    let without = |text: &str| {
        let start = text.find("[[coupling]]").expect("couplings");
        let end = text.find("# Every subsystem's certifier").expect("end");
        format!("{}{}", &text[..start], &text[end..])
    };
    let base = without(EXAMPLE_CONFIG);
    let want = parse(EXAMPLE_CONFIG, "example").expect("valid").network.couplings;
    for (file, layout, body) in [
        ("dense.txt", "dense", "0 0.4\n0.4 0\n"),
        ("triplets.txt", "triplets", "i,j,gamma\n0,1,0.4\n1,0,0.4\n"),
    ] {
        std::fs::write(dir.join(file), body).expect("write");
        let text = base.replacen(
            "[network]",
            &format!("[network]\ngains = \"{file}\"\ngains_format = \"{layout}\""),
            1,
        );
        // A relative path is read next to the configuration file.
        let cfg = parse(&text, cfg_path.to_str().expect("utf8")).expect(layout);
        let mut got = cfg.network.couplings.clone();
        got.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
        let mut expected = want.clone();
        expected.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
        assert_eq!(got, expected, "{layout}");
    }
    let path = cfg_path.to_str().expect("utf8");
    let with =
        |extra: &str| EXAMPLE_CONFIG.replacen("[network]", &format!("[network]\n{extra}"), 1);
    let message = |text: &str| parse(text, path).expect_err("refused").to_string();
    assert!(message(&with("gains = \"dense.txt\"")).contains("keep one"));
    let missing = base.replacen("[network]", "[network]\ngains = \"nowhere.txt\"", 1);
    assert!(message(&missing).contains("cannot read"));
    std::fs::write(dir.join("bad.txt"), "0 0.4 1\n0.4 0\n").expect("write");
    let shape = base.replacen("[network]", "[network]\ngains = \"bad.txt\"", 1);
    assert!(message(&shape).contains("2 rows of 2"));
    std::fs::write(dir.join("neg.txt"), "0,1,-0.4\n").expect("write");
    let negative = base.replacen(
        "[network]",
        "[network]\ngains = \"neg.txt\"\ngains_format = \"triplets\"",
        1,
    );
    assert!(message(&negative).contains("γ must be finite and >= 0"));
    std::fs::write(dir.join("far.txt"), "0,7,0.4\n").expect("write");
    let far = base.replacen(
        "[network]",
        "[network]\ngains = \"far.txt\"\ngains_format = \"triplets\"",
        1,
    );
    assert!(parse(&far, path).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}
