//! The subsystems one timely worker owns, advanced through each complete segment.

use streamcert_certificate::Certifier;
use streamcert_network::{LocalSnapshot, NetworkConfig};

use crate::{Sample, ShardMsg};

/// A subsystem's certifier on its worker, with its newest snapshot.
struct Owned {
    certifier: Certifier,
    snapshot: Option<LocalSnapshot>,
    failed: bool,
}

/// The subsystems a worker owns (`i mod workers == worker index`), with their snapshots.
pub(crate) struct Shard {
    owned: Vec<Option<Owned>>,
    touched: Vec<usize>,
}

impl Shard {
    pub(crate) fn new(cfg: &NetworkConfig, index: usize, peers: usize) -> Self {
        let owned = (0..cfg.subsystems.len())
            .map(|i| {
                (i % peers == index).then(|| Owned {
                    // The configuration was validated by `run`.
                    certifier: Certifier::new(cfg.subsystems[i].certifier.clone())
                        .expect("validated configuration"),
                    snapshot: None,
                    failed: false,
                })
            })
            .collect();
        Self { owned, touched: Vec::new() }
    }

    /// Advance through one complete segment's samples in row order; hand out a failure per
    /// failing subsystem and then the snapshot of every subsystem the segment advanced.
    pub(crate) fn segment(
        &mut self,
        cfg: &NetworkConfig,
        mut samples: Vec<Sample>,
        mut give: impl FnMut(ShardMsg),
    ) {
        samples.sort_by_key(|s| s.row);
        self.touched.clear();
        for s in samples {
            let i = s.index as usize;
            let Some(Some(o)) = self.owned.get_mut(i) else { continue };
            if o.failed {
                continue;
            }
            let p = o.certifier.config().regression.outputs.min(s.values.len());
            let (y, u) = s.values.split_at(p);
            match o.certifier.push(s.t, y, u) {
                Ok(ev) => {
                    let v = *ev.verdict(cfg.certificate);
                    match &mut o.snapshot {
                        Some(snap) => snap.update(s.t, v, &o.certifier),
                        None => o.snapshot = Some(LocalSnapshot::new(s.t, v, &o.certifier)),
                    }
                    self.touched.push(i);
                }
                Err(e) => {
                    o.failed = true;
                    give(ShardMsg::Failed {
                        row: s.row,
                        line: s.line,
                        index: s.index,
                        message: e.to_string(),
                    });
                }
            }
        }
        self.touched.sort_unstable();
        self.touched.dedup();
        for &i in &self.touched {
            if let Some(Some(Owned { snapshot: Some(snapshot), .. })) = self.owned.get(i) {
                let index = u32::try_from(i).unwrap_or(u32::MAX);
                give(ShardMsg::Snapshot { index, snapshot: snapshot.into() });
            }
        }
    }
}
