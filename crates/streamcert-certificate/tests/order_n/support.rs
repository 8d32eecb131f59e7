//! What the order-`n` integration tests share: loops of any order simulated exactly (the
//! dynamics crate's [`ObservableLoop`], 100 Hz, a seeded SplitMix64 stream) and a map over
//! seeds on two threads.

pub(crate) use streamcert_dynamics::ObservableLoop as Loop;

/// `f` over `seeds` on two threads, in seed order.
pub(crate) fn par_map<T: Send>(seeds: std::ops::Range<u64>, f: impl Fn(u64) -> T + Sync) -> Vec<T> {
    let seeds: Vec<u64> = seeds.collect();
    let (left, right) = seeds.split_at(seeds.len() / 2);
    std::thread::scope(|s| {
        let a = s.spawn(|| left.iter().map(|&k| f(k)).collect::<Vec<_>>());
        let b = right.iter().map(|&k| f(k)).collect::<Vec<_>>();
        let mut all = a.join().unwrap();
        all.extend(b);
        all
    })
}
