//! The encoder's clusters of contexts: adjacent energy classes of a level group merged
//! while merging saves bits (data and tables).

use super::passes::{ALPHABET, FINE};
use crate::entropy::rans;

/// Estimated bits of coding `counts` with its own table (data and table).
fn cost(counts: &[u64]) -> f64 {
    let n: u64 = counts.iter().sum();
    if n == 0 {
        return 7.0;
    }
    let f = rans::normalize(counts);
    let data: f64 = counts
        .iter()
        .zip(&f)
        .filter(|(c, _)| **c > 0)
        .map(|(&c, &f)| c as f64 * (rans::PREC as f64 - (f as f64).log2()))
        .sum();
    data + rans::table_bits(&f) as f64
}

/// Cluster each group's energy classes into runs of adjacent classes (greedy: merge the
/// neighbouring pair that saves the most bits while one does). Returns per context its
/// cluster and the clusters' summed counts.
pub(super) fn cluster(counts: &[[u64; ALPHABET]]) -> (Vec<u16>, Vec<[u64; ALPHABET]>) {
    let mut map = vec![0u16; counts.len()];
    let mut out: Vec<[u64; ALPHABET]> = Vec::new();
    for g in 0..counts.len() / FINE {
        // Runs: (first class, counts, cost).
        let mut runs: Vec<(usize, [u64; ALPHABET], f64)> = (0..FINE)
            .map(|c| {
                let h = counts[g * FINE + c];
                (c, h, cost(&h))
            })
            .collect();
        loop {
            let mut best: Option<(usize, f64, [u64; ALPHABET], f64)> = None;
            for k in 0..runs.len().saturating_sub(1) {
                let mut m = runs[k].1;
                for (a, b) in m.iter_mut().zip(&runs[k + 1].1) {
                    *a += b;
                }
                let c = cost(&m);
                let gain = runs[k].2 + runs[k + 1].2 - c;
                if gain > 0.0 && best.as_ref().is_none_or(|b| gain > b.1) {
                    best = Some((k, gain, m, c));
                }
            }
            let Some((k, _, m, c)) = best else { break };
            runs[k].1 = m;
            runs[k].2 = c;
            runs.remove(k + 1);
        }
        for (r, run) in runs.iter().enumerate() {
            let end = runs.get(r + 1).map_or(FINE, |n| n.0);
            for c in run.0..end {
                map[g * FINE + c] = out.len() as u16;
            }
            out.push(run.1);
        }
    }
    (map, out)
}
