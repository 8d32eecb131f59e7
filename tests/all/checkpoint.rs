//! The binary checkpoint's packed block rings (`certifier/pack.rs`): the resume bit for bit,
//! against the JSON export (every ring whole) and the unpacked binary of version 5.

use streamcert::certificate::{
    CHECKPOINT_UNPACKED_VERSION, CHECKPOINT_VERSION, Certifier, Encoding, encode, seal, unseal,
};
use streamcert::dynamics::LinearScenario;

use crate::calibrated::{calibrated, short_window_plant};
use crate::support::{json_payload, resume_matches, run};

/// The default calibrated certificate (both model guards, the change guard, the anchored
/// window) past the wrap of its longest window's ring (2400 columns): the packed checkpoint
/// resumes bit for bit (every row, and the whole state at the end, scratch included),
/// restores the state the JSON export does, is under 0.6 of the unpacked binary's size (0.52
/// measured), and the unpacked binary still restores under its own version.
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
        let (packed_len, unpacked_len) = (packed.len(), sealed.len());
        assert!(5 * packed_len < 3 * unpacked_len, "{packed_len} B packed, {unpacked_len} B whole");
    }
}
