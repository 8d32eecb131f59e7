//! The benches' G5 data: node b through experiment 1's schedule.

/// `rows` steps of G5 under experiment 1's schedule (seed 0), as `streamcert simulate g5`
/// writes them.
pub(crate) fn g5_csv(rows: usize) -> String {
    let mut out = Vec::new();
    streamcert_pipeline::simulate::run(
        streamcert::experiments::Experiment::One,
        streamcert::dynamics::Coupling::Cascade,
        0,
        Some(rows - 1),
        None,
        &mut out,
    )
    .expect("simulate");
    String::from_utf8(out).expect("utf8")
}
