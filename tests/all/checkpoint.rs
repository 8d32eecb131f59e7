//! The binary checkpoint's compact block rings: the sliding rings left out and rebuilt from
//! the sample trail (`calibrated/replay.rs`), the anchored ring packed (`certifier/pack.rs`);
//! the resume bit for bit, against the JSON export (every ring whole) and the binary
//! versions 5 and 6 still read.

use streamcert::certificate::{
    CHECKPOINT_PACKED_VERSION, CHECKPOINT_UNPACKED_VERSION, CHECKPOINT_VERSION, Calibration,
    Certifier, CertifierConfig, Encoding, NonlinearConfig, encode, seal, unseal,
};
use streamcert::dynamics::{LinearScenario, Trajectory};
use streamcert::regression::Model;

use crate::calibrated::{calibrated, short_window_plant};
use crate::support::{coupled_pair, json_payload, resume_matches, run};

/// The default calibrated certificate (both model guards, the change guard, the anchored
/// window) past the wrap of its longest window's ring (2400 columns): the packed checkpoint
/// resumes bit for bit (every row, and the whole state at the end, scratch included),
/// restores the state the JSON export does, is under 0.3 of the unpacked binary's size, and
/// the unpacked binary still restores under versions 5 and 6.
#[test]
fn packed_rings_resume_bit_for_bit_and_the_unpacked_version_still_reads() {
    let traj = run(&LinearScenario { steps: 6000, ..short_window_plant() }, 11);
    let cfg = calibrated(1, vec![-1.5], 150, 10);
    let mut whole = Certifier::new(cfg.clone()).expect("valid");
    let all: Vec<_> = (0..traj.len())
        .map(|k| whole.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid"))
        .collect();
    assert!(all.iter().any(|e| e.calibrated.open), "the calibrated gate opened");
    for split in [2222, 4567] {
        let (text, second) = resume_matches(&cfg, &traj, &all, split);
        // The whole state, scratch included, as the uninterrupted run's.
        assert_eq!(second, whole, "the state at the end after a restore at {split}");
        if split < 2400 {
            continue;
        }
        // Version 5: the same state in CBOR with every ring whole (the JSON export's
        // payload re-encoded), under its own header.
        let mut first = Certifier::new(cfg.clone()).expect("valid");
        for k in 0..split {
            first.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid");
        }
        let packed = first.checkpoint().expect("serialises");
        let state: serde_json::Value = serde_json::from_str(json_payload(&text)).expect("JSON");
        let unpacked = encode(&state, Encoding::Binary).expect("encodes");
        let sealed = seal(&unpacked, Encoding::Binary, &cfg).expect("seals");
        let header = |v: u32| format!("streamcert-checkpoint {v} ");
        let v5 = [
            header(CHECKPOINT_UNPACKED_VERSION).as_bytes(),
            &sealed[header(CHECKPOINT_VERSION).len()..],
        ]
        .concat();
        assert_eq!(unseal::<()>(&v5, None).expect("opens").encoding, Encoding::Binary);
        // Restored against restored: a live state also holds its latest look's scratch and
        // verdict, which a restore recomputes at the next step.
        let restored = Certifier::restore(&packed).expect("restores");
        assert_eq!(Certifier::restore(&v5).expect("version 5 restores"), restored);
        // A state written before the sample trail (version 6: the same decoder; its rings
        // here whole) restores with an empty trail, so its next checkpoint writes the rings
        // (packed) and restores to the same state; the rows after it are the uninterrupted
        // run's.
        let mut old_state = state.clone();
        old_state["calibrated"].as_object_mut().expect("a map").remove("trail");
        let old =
            seal(&encode(&old_state, Encoding::Binary).expect("encodes"), Encoding::Binary, &cfg)
                .expect("seals");
        let v6 = [
            header(CHECKPOINT_PACKED_VERSION).as_bytes(),
            &old[header(CHECKPOINT_VERSION).len()..],
        ]
        .concat();
        let from_v6 = Certifier::restore(&v6).expect("version 6 restores");
        let again = from_v6.checkpoint().expect("serialises");
        assert_eq!(calibrated_entry(&again, "rings_replayed"), None);
        let mut resumed = Certifier::restore(&again).expect("restores");
        assert_eq!(resumed, from_v6);
        for k in split..traj.len() {
            let ev = resumed.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid");
            assert_eq!(ev, all[k], "row {k} after a restore of version 6 at {split}");
        }
        let (packed_len, unpacked_len) = (packed.len(), sealed.len());
        assert!(
            10 * packed_len < 3 * unpacked_len,
            "{packed_len} B packed, {unpacked_len} B whole"
        );
    }
}

/// The calibrated state's `key` entry of a binary checkpoint's payload.
fn calibrated_entry(sealed: &[u8], key: &str) -> Option<ciborium::Value> {
    let payload = &sealed[sealed.iter().position(|&b| b == b'\n')? + 1..];
    let value: ciborium::Value = ciborium::from_reader(payload).ok()?;
    let get = |v: &ciborium::Value, k: &str| {
        v.as_map()?.iter().find(|(n, _)| n.as_text() == Some(k)).map(|(_, v)| v.clone())
    };
    get(&get(&value, "calibrated")?, key)
}

/// The entry `key` of the map `v`.
fn field<'a>(v: &'a mut ciborium::Value, key: &str) -> &'a mut ciborium::Value {
    let map = v.as_map_mut().expect("a map");
    &mut map.iter_mut().find(|(k, _)| k.as_text() == Some(key)).expect("the entry").1
}

/// The payload of `sealed` with the calibrated state's sample trail's entry `key` set to
/// `to`.
fn edit_trail(sealed: &[u8], key: &str, to: ciborium::Value) -> Vec<u8> {
    let payload = &sealed[sealed.iter().position(|&b| b == b'\n').expect("header") + 1..];
    let mut value: ciborium::Value = ciborium::from_reader(payload).expect("CBOR");
    let trail = field(field(&mut value, "calibrated"), "trail");
    *field(trail, key) = to;
    let mut out = Vec::new();
    ciborium::into_writer(&value, &mut out).expect("encodes");
    out
}

/// The default calibrated certificate with a gap (the regression and every ring reset) at
/// sample 3000: at every split (before the first column, before the rings fill, just before
/// and after the gap, past the longest window's wrap, one sample before the end) the binary
/// checkpoint leaves the sliding block rings out (`rings_replayed`, the linear ring's blocks
/// empty) and the resume is bit for bit: every row, every serialised bit of the state at the
/// end, and every field once a look has recomputed the scratch a checkpoint does not carry.
/// With the trail cut to nothing, or its capacity made huge (the checksum made valid again),
/// the restore is refused, saying why.
#[test]
fn the_sliding_rings_are_rebuilt_from_the_sample_trail_bit_for_bit() {
    let traj = run(&LinearScenario { steps: 6000, ..short_window_plant() }, 12);
    let cfg = calibrated(1, vec![-1.5], 150, 10);
    let push_all = |c: &mut Certifier, from: usize, to: usize| -> Vec<_> {
        (from..to)
            .map(|k| {
                if k == 3000 {
                    c.gap();
                }
                c.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid")
            })
            .collect()
    };
    let mut whole = Certifier::new(cfg.clone()).expect("valid");
    let all = push_all(&mut whole, 0, traj.len());
    assert!(all.iter().any(|e| e.calibrated.open), "the calibrated gate opened");
    let json = |c: &Certifier| c.checkpoint_json().expect("serialises");
    for split in [3, 700, 2999, 3004, 3400, 5999] {
        let mut first = Certifier::new(cfg.clone()).expect("valid");
        push_all(&mut first, 0, split);
        let sealed = first.checkpoint().expect("serialises");
        let replayed = calibrated_entry(&sealed, "rings_replayed");
        assert_eq!(replayed, Some(ciborium::Value::Bool(true)), "split {split}");
        let windows = calibrated_entry(&sealed, "windows").expect("the linear windows");
        let blocks = windows.as_map().and_then(|m| {
            m.iter().find(|(k, _)| k.as_text() == Some("blocks")).map(|(_, v)| v.clone())
        });
        assert_eq!(blocks, Some(ciborium::Value::Array(Vec::new())), "split {split}");
        let mut second = Certifier::restore(&sealed)
            .unwrap_or_else(|e| panic!("the checkpoint at {split} restores: {e}"));
        assert_eq!(push_all(&mut second, split, traj.len()), all[split..], "after {split}");
        assert_eq!(json(&second), json(&whole), "the state at the end after {split}");
        if split < 5999 {
            assert_eq!(second, whole, "every field at the end after {split}");
        }
        if split == 5999 {
            // No rows (the varint 0): the rings cannot be rebuilt.
            let cut = edit_trail(&sealed, "rows", ciborium::Value::Bytes(vec![0]));
            let err = Certifier::restore(seal(&cut, Encoding::Binary, &cfg).expect("seals"))
                .expect_err("a trail that does not reach back is refused");
            assert!(err.to_string().contains("does not reach back"), "{err}");
            // A capacity of 2⁶⁰ samples: refused against the configuration, nothing allocated.
            let huge = edit_trail(&sealed, "cap", ciborium::Value::Integer((1u64 << 60).into()));
            let err = Certifier::restore(seal(&huge, Encoding::Binary, &cfg).expect("seals"))
                .expect_err("a trail of another capacity is refused");
            assert!(err.to_string().contains("does not fit its configuration"), "{err}");
        }
    }
}

/// Every shape the calibrated state takes, checkpointed past the longest window's wrap (and
/// one just before it): two outputs; two instrument intervals with a lag of two and batches
/// of two blocks; the paper's model through the origin without guards; outputs in stated
/// units (two outputs); the nonlinear certificate beside the calibrated one. In each the binary checkpoint
/// leaves the sliding rings out and the resume is the uninterrupted run's, every row and every
/// serialised bit of the state at the end.
#[test]
fn the_sliding_rings_are_rebuilt_in_every_shape_of_the_calibrated_state() {
    let base = calibrated(1, vec![-1.5], 150, 10);
    let cal = base.calibration.expect("calibrated");
    let scalar = run(&LinearScenario { steps: 3200, ..short_window_plant() }, 21);
    let pair = run(&coupled_pair(short_window_plant(), 3200), 22);
    let mut origin = base.clone();
    origin.regression.model = Model::ThroughOrigin;
    origin.calibration = Some(cal.unguarded());
    let cases: Vec<(&str, CertifierConfig, &Trajectory)> = vec![
        ("two outputs", calibrated(2, vec![-1.5, 0.0, 0.0, -1.5], 150, 10), &pair),
        (
            "two intervals, lag 2, batches of 2",
            CertifierConfig {
                calibration: Some(Calibration {
                    instrument_intervals: 2,
                    instrument_lag: 2,
                    batch_blocks: 2,
                    ..cal
                }),
                ..base.clone()
            },
            &scalar,
        ),
        ("through the origin, unguarded", origin, &scalar),
        (
            "two outputs in stated units",
            CertifierConfig {
                metric: Some(vec![1000.0, 0.5]),
                ..calibrated(2, vec![-1.5, 0.0, 0.0, -1.5], 150, 10)
            },
            &pair,
        ),
        (
            "with the nonlinear certificate",
            CertifierConfig { nonlinear: Some(NonlinearConfig::with_degree(3)), ..base.clone() },
            &scalar,
        ),
    ];
    for (name, cfg, traj) in cases {
        let mut whole = Certifier::new(cfg.clone()).expect("valid");
        let all: Vec<_> = (0..traj.len())
            .map(|k| whole.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid"))
            .collect();
        for split in [2390, 3100] {
            let mut first = Certifier::new(cfg.clone()).expect("valid");
            for k in 0..split {
                first.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid");
            }
            let sealed = first.checkpoint().expect("serialises");
            let replayed = calibrated_entry(&sealed, "rings_replayed");
            assert_eq!(replayed, Some(ciborium::Value::Bool(true)), "{name}, split {split}");
            let mut second = Certifier::restore(&sealed)
                .unwrap_or_else(|e| panic!("{name}: the checkpoint at {split} restores: {e}"));
            for k in split..traj.len() {
                let ev = second.push(traj.t[k], traj.output(k), traj.input(k)).expect("valid");
                assert_eq!(ev, all[k], "{name}: row {k} after a restore at {split}");
            }
            let json = |c: &Certifier| c.checkpoint_json().expect("serialises");
            assert_eq!(json(&second), json(&whole), "{name}: the state after {split}");
        }
    }
}
