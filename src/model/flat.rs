//! Flat regions: connected areas of one exact value (sea, lakes, reservoirs, building pads)
//! that every method must decode to exactly that value. Finding them (encoder) and
//! labelling a flat-sample bitmap into regions (encoder and decoder alike).

use super::Raster;

/// Components of one value smaller than this many samples are not worth a section entry:
/// a value and its outline cost more than what the method spends on them, and at loose
/// bounds the method keeps them within the bound anyway. Measured (benches/README.md,
/// "Flat regions"): 4096 against 1024 takes Crater Lake's three terraces beside the lake
/// out (3 %: 2 231 → 1 866 bytes with the per-sample bitmap) and changes nothing on the sea
/// of Kauai or Kattegat.
pub const MIN_REGION: usize = 4096;

/// A kept region (its whole blocks, as the decoder labels them) of fewer samples goes:
/// 16 blocks. Lower than [`MIN_REGION`] because a narrow waist or an island cuts a large
/// lake's blocks into pieces (Crater Lake's 8 916 samples keep 5 632 in two pieces).
pub const MIN_PIECE: usize = 1024;

/// Side of the aligned blocks flat regions are kept in (the section's coding 1): a region
/// keeps the blocks wholly inside it, so its outline costs a bit per block edge instead of
/// a few per sample of a jagged shore, and the bitmap codes 64 times fewer bits. The
/// samples of the region outside those blocks (a shore's fringe under 8 samples wide) are
/// left to the method, within the bound.
pub const BLOCK: usize = 8;

/// Label the 4-connected components of `flat` (a `w`-wide bitmap) in raster order: the
/// component holding the first flat sample is 1, the next one not yet labelled 2, and so
/// on; 0 marks samples that are not flat. Returns the labels and the component count. The
/// definition (a flood fill, sample by sample) that [`label_runs`] is tested against.
#[cfg(test)]
pub(crate) fn label(flat: &[bool], w: usize) -> (Vec<u32>, u32) {
    let n = flat.len();
    let mut lab = vec![0u32; n];
    let mut count = 0u32;
    let mut stack = Vec::new();
    for s in 0..n {
        if !flat[s] || lab[s] != 0 {
            continue;
        }
        count += 1;
        lab[s] = count;
        stack.push(s);
        while let Some(i) = stack.pop() {
            let x = i % w;
            let mut visit = |j: usize| {
                if flat[j] && lab[j] == 0 {
                    lab[j] = count;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w && i + 1 < n {
                visit(i + 1);
            }
            if i >= w {
                visit(i - w);
            }
            if i + w < n {
                visit(i + w);
            }
        }
    }
    (lab, count)
}

/// The 4-connected components of `flat` as runs: every maximal run of flat samples along a
/// row as (first sample index, length, component − 1), components numbered in raster order
/// from 1 as `label` numbers them, and the component count. The same components and
/// numbers as `label` (a run lies in one 4-connected component; runs of neighbouring rows
/// that share a column are joined), found by union–find over the runs instead of a flood
/// fill over the samples: a sea of millions of samples is a few thousand runs. `label`, the
/// flood fill, stays as the definition the tests hold it to.
pub(crate) fn label_runs(flat: &[bool], w: usize) -> (Vec<(u64, u32, u32)>, u32) {
    let w = w.max(1);
    // (first sample index, length) per run, rows in order; union–find parents.
    let mut runs: Vec<(u64, u32)> = Vec::new();
    let mut parent: Vec<u32> = Vec::new();
    fn root(parent: &mut [u32], mut a: u32) -> u32 {
        while parent[a as usize] != a {
            let up = parent[parent[a as usize] as usize];
            parent[a as usize] = up;
            a = up;
        }
        a
    }
    let mut prev = 0..0;
    for (y, row) in flat.chunks(w).enumerate() {
        let first = runs.len();
        let mut x = 0;
        while x < row.len() {
            if !row[x] {
                x += 1;
                continue;
            }
            let from = x;
            while x < row.len() && row[x] {
                x += 1;
            }
            let id = runs.len() as u32;
            runs.push(((y * w + from) as u64, (x - from) as u32));
            parent.push(id);
        }
        // Join each run of this row with the runs of the row above that share a column.
        let mut k = prev.start;
        for j in first..runs.len() {
            let (a0, a1) = (
                runs[j].0 as usize % w,
                runs[j].0 as usize % w + runs[j].1 as usize,
            );
            while k < prev.end {
                let b0 = runs[k].0 as usize % w;
                let b1 = b0 + runs[k].1 as usize;
                if b1 <= a0 {
                    k += 1;
                    continue;
                }
                if b0 >= a1 {
                    break;
                }
                let (ra, rb) = (root(&mut parent, j as u32), root(&mut parent, k as u32));
                // The smaller run index is the root, so a component's root is its first run.
                if ra != rb {
                    parent[ra.max(rb) as usize] = ra.min(rb);
                }
                if b1 > a1 {
                    break;
                }
                k += 1;
            }
        }
        prev = first..runs.len();
    }
    // Number the components in the order of their first runs (their first samples).
    let mut number = vec![0u32; runs.len()];
    let mut count = 0u32;
    let mut out = Vec::with_capacity(runs.len());
    for (j, &(start, len)) in runs.iter().enumerate() {
        let r = root(&mut parent, j as u32) as usize;
        if number[r] == 0 {
            count += 1;
            number[r] = count;
        }
        out.push((start, len, number[r] - 1));
    }
    (out, count)
}

/// Label `id` into `comp` over the 4-connected component of valid samples equal to sample
/// `s`'s value (unlabelled so far), a row span at a time (a scanline flood fill: the same
/// samples as a fill sample by sample, in far fewer steps over a sea); returns its size.
fn fill_span(r: &Raster, comp: &mut [u32], stack: &mut Vec<usize>, s: usize, id: u32) -> usize {
    let (w, n) = (r.width, r.len());
    // The same bits (0 and −0 are different values to a lossless encode).
    let v = r.data[s].to_bits();
    let open =
        |comp: &[u32], j: usize| comp[j] == u32::MAX && r.is_valid(j) && r.data[j].to_bits() == v;
    let mut size = 0;
    stack.push(s);
    while let Some(i) = stack.pop() {
        if !open(comp, i) {
            continue;
        }
        let row = i - i % w;
        let (mut a, mut b) = (i, i);
        while a > row && open(comp, a - 1) {
            a -= 1;
        }
        while b + 1 < row + w && open(comp, b + 1) {
            b += 1;
        }
        comp[a..=b].fill(id);
        size += b - a + 1;
        // One seed per run of open samples in the rows above and below the span.
        for other in [(row >= w).then(|| row - w), (row + w < n).then(|| row + w)]
            .into_iter()
            .flatten()
        {
            let mut in_run = false;
            for x in a - row..=b - row {
                let j = other + x;
                let o = open(comp, j);
                if o && !in_run {
                    stack.push(j);
                }
                in_run = o;
            }
        }
    }
    size
}

/// The flat regions of `r`: per sample its region's value, NaN outside every region; `None`
/// when there is none. A region is the union of the aligned [`BLOCK`]² blocks (clipped at
/// the raster's edges) whose samples are all valid and lie in one 4-connected component of
/// one exact value (the same bits: 0 and −0 differ) of at least [`MIN_REGION`] samples; a block touching a kept block of
/// another component is left out (so that [`label_runs`] of the result gives regions of one
/// value each to a decoder that sees only the blocks), and so is a region of fewer than
/// [`MIN_PIECE`] samples.
pub(crate) fn find(r: &Raster) -> Option<Vec<f64>> {
    let (w, n) = (r.width, r.len());
    if w == 0 || n == 0 {
        return None;
    }
    let h = n / w;
    let (bw, bh) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
    // Blocks (clipped at the edges) whose samples are all valid and of one value: the only
    // ones a region can keep, since a block lies wholly in a component of one value only
    // if it is uniform, and a uniform block is 4-connected, so it lies in one component.
    // On a raster without flat areas this looks at a sample or two per block and ends
    // here, without labelling every sample's component.
    let uniform = |bx: usize, by: usize| {
        let (x0, y0) = (bx * BLOCK, by * BLOCK);
        let (x1, y1) = ((x0 + BLOCK).min(w), (y0 + BLOCK).min(h));
        let v = r.data[y0 * w + x0].to_bits();
        (y0..y1)
            .all(|y| (y * w + x0..y * w + x1).all(|i| r.is_valid(i) && r.data[i].to_bits() == v))
    };
    let cand: Vec<usize> = (0..bw * bh).filter(|&b| uniform(b % bw, b / bw)).collect();
    if cand.is_empty() {
        return None;
    }
    // The components of equal value that hold a candidate block (4-connected, valid),
    // labelled from the blocks' first samples; their sizes.
    let mut comp = vec![u32::MAX; n];
    let mut sizes: Vec<usize> = Vec::new();
    let mut stack = Vec::new();
    let mut block = vec![u32::MAX; bw * bh];
    for &b in &cand {
        let s = (b / bw) * BLOCK * w + (b % bw) * BLOCK;
        if comp[s] == u32::MAX {
            let id = sizes.len() as u32;
            sizes.push(fill_span(r, &mut comp, &mut stack, s, id));
        }
        // Per block the component it lies wholly in (of at least MIN_REGION samples).
        let c = comp[s];
        if sizes[c as usize] >= MIN_REGION {
            block[b] = c;
        }
    }
    let kept = kept_blocks(&block, bw);
    if !kept.contains(&true) {
        return None;
    }
    // The kept blocks' samples, row by row and block by block.
    let mut flat = vec![false; n];
    for (y, row) in flat.chunks_mut(w).enumerate() {
        let ks = &kept[(y / BLOCK) * bw..(y / BLOCK + 1) * bw];
        for (cell, _) in row.chunks_mut(BLOCK).zip(ks).filter(|(_, k)| **k) {
            cell.fill(true);
        }
    }
    // Regions (as a decoder labels them) below the minimum go.
    let (runs, count) = label_runs(&flat, w);
    let mut region_size = vec![0usize; count as usize];
    for &(_, len, l) in &runs {
        region_size[l as usize] += len as usize;
    }
    for &(start, len, l) in &runs {
        if region_size[l as usize] < MIN_PIECE {
            flat[start as usize..start as usize + len as usize].fill(false);
        }
    }
    flat_values(r, &flat)
}

/// The samples of the flat regions (NaN elsewhere), or `None` when there is none.
fn flat_values(r: &Raster, flat: &[bool]) -> Option<Vec<f64>> {
    flat.contains(&true).then(|| {
        flat.iter()
            .zip(&r.data)
            .map(|(&f, &v)| if f { v } else { f64::NAN })
            .collect()
    })
}

/// Which of `bw`-wide row-major blocks are kept: a block wholly in one component
/// (`block[b]`, `u32::MAX` for none) goes when it touches a block of another component.
fn kept_blocks(block: &[u32], bw: usize) -> Vec<bool> {
    let n = block.len();
    let mut drop = vec![false; n];
    for b in 0..n {
        if block[b] == u32::MAX {
            continue;
        }
        for j in [
            (b % bw + 1 < bw).then(|| b + 1),
            (b + bw < n).then(|| b + bw),
        ]
        .into_iter()
        .flatten()
        {
            if block[j] != u32::MAX && block[j] != block[b] {
                drop[b] = true;
                drop[j] = true;
            }
        }
    }
    (0..n).map(|b| block[b] != u32::MAX && !drop[b]).collect()
}

#[cfg(test)]
mod tests {
    /// `label_runs` against the flood fill of `label`, run by run.
    fn runs_of_label(flat: &[bool], w: usize) -> (Vec<(u64, u32, u32)>, u32) {
        let (lab, count) = label(flat, w);
        let mut runs = Vec::new();
        for (y, row) in lab.chunks(w).enumerate() {
            let mut x = 0;
            while x < row.len() {
                let (l, from) = (row[x], x);
                while x < row.len() && row[x] == l {
                    x += 1;
                }
                if l != 0 {
                    runs.push(((y * w + from) as u64, (x - from) as u32, l - 1));
                }
            }
        }
        (runs, count)
    }

    #[test]
    fn run_labels_are_the_flood_fills() {
        let mut rng = crate::testutil::Rng(99);
        let mut next = move || rng.next() >> 33;
        for case in 0..300 {
            let (w, h) = (1 + next() as usize % 40, 1 + next() as usize % 30);
            let density = next() % 100;
            let mut flat: Vec<bool> = (0..w * h).map(|_| next() % 100 < density).collect();
            if case % 3 == 0 {
                // Combs and U shapes: components that join only rows below their starts.
                for (i, f) in flat.iter_mut().enumerate() {
                    let (x, y) = (i % w, i / w);
                    *f = (x % 4 == 0 && y + 1 < h) || y + 1 == h || (x % 4 == 2 && y == 0);
                }
            }
            assert_eq!(
                label_runs(&flat, w),
                runs_of_label(&flat, w),
                "case {case}: {w}x{h}"
            );
        }
    }

    use super::*;
    use crate::model::SampleType;
    use crate::testutil::{Rng, for_each_corpus, load_raw};

    // The definition, written out (the encoder's code before it labelled only the
    // components that hold a uniform block): every sample's component of equal value
    // labelled, then the blocks lying wholly in one of ≥ MIN_REGION samples.
    fn find_reference(r: &Raster) -> Option<Vec<f64>> {
        let (w, n) = (r.width, r.len());
        if w == 0 || n == 0 {
            return None;
        }
        let h = n / w;
        // Components of equal value.
        let mut comp = vec![u32::MAX; n];
        let mut sizes: Vec<usize> = Vec::new();
        let mut stack = Vec::new();
        for s in 0..n {
            if comp[s] != u32::MAX || !r.is_valid(s) {
                continue;
            }
            let id = sizes.len() as u32;
            let v = r.data[s];
            let mut size = 0usize;
            comp[s] = id;
            stack.push(s);
            while let Some(i) = stack.pop() {
                size += 1;
                let x = i % w;
                let nb = [
                    (x > 0).then(|| i - 1),
                    (x + 1 < w).then(|| i + 1),
                    (i >= w).then(|| i - w),
                    (i + w < n).then(|| i + w),
                ];
                for j in nb.into_iter().flatten() {
                    if comp[j] == u32::MAX && r.is_valid(j) && r.data[j] == v {
                        comp[j] = id;
                        stack.push(j);
                    }
                }
            }
            sizes.push(size);
        }
        // Per block the component it lies wholly in (of at least MIN_REGION samples), if any.
        let (bw, bh) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
        let mut block = vec![u32::MAX; bw * bh];
        for by in 0..bh {
            for bx in 0..bw {
                let (x0, y0) = (bx * BLOCK, by * BLOCK);
                let (x1, y1) = ((x0 + BLOCK).min(w), (y0 + BLOCK).min(h));
                let c = comp[y0 * w + x0];
                if c == u32::MAX || sizes[c as usize] < MIN_REGION {
                    continue;
                }
                if (y0..y1).all(|y| comp[y * w + x0..y * w + x1].iter().all(|&k| k == c)) {
                    block[by * bw + bx] = c;
                }
            }
        }
        // (The block step is `find`'s own: this reference checks the components and regions.)
        let kept = kept_blocks(&block, bw);
        let mut flat: Vec<bool> = (0..n)
            .map(|i| kept[(i / w / BLOCK) * bw + (i % w) / BLOCK])
            .collect();
        // Regions (as a decoder labels them) below the minimum go.
        let (lab, count) = label(&flat, w);
        let mut region_size = vec![0usize; count as usize + 1];
        for &l in &lab {
            region_size[l as usize] += 1;
        }
        for i in 0..n {
            flat[i] &= region_size[lab[i] as usize] >= MIN_PIECE;
        }
        flat_values(r, &flat)
    }

    fn same(a: &Option<Vec<f64>>, b: &Option<Vec<f64>>) -> bool {
        match (a, b) {
            (None, None) => true,
            (Some(a), Some(b)) => {
                a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
            }
            _ => false,
        }
    }

    /// Terraces, lakes touching each other, nodata holes, plateaus below MIN_REGION, a
    /// narrow waist: every layout gives the reference's regions.
    #[test]
    fn find_matches_the_definition() {
        let mut rng = Rng(11);
        let mut found = 0;
        for case in 0..40 {
            let (w, h) = (40 + rng.below(160) as usize, 30 + rng.below(150) as usize);
            let mut data = vec![0f64; w * h];
            for (i, d) in data.iter_mut().enumerate() {
                *d = (i % 7) as f64 * 0.5 + rng.below(3) as f64;
            }
            for _ in 0..1 + rng.below(5) {
                let (x0, y0) = (rng.below(w as u64) as usize, rng.below(h as u64) as usize);
                let (rw, rh) = (1 + rng.below(120) as usize, 1 + rng.below(120) as usize);
                let v = [10.0, 20.0, 10.0, -3.5][rng.below(4) as usize];
                for y in y0..(y0 + rh).min(h) {
                    for x in x0..(x0 + rw).min(w) {
                        data[y * w + x] = v;
                    }
                }
            }
            let nodata = (case % 3 == 0).then_some(-9999.0);
            if nodata.is_some() {
                for _ in 0..rng.below(300) {
                    data[rng.below((w * h) as u64) as usize] = -9999.0;
                }
            }
            let r = Raster::from_values(w, h, data, nodata, SampleType::F32).unwrap();
            let (got, want) = (find(&r), find_reference(&r));
            assert!(same(&got, &want), "case {case}: {w}x{h}");
            found += usize::from(got.is_some());
        }
        // Both outcomes occur: some layouts keep regions, others none.
        assert!(
            (5..35).contains(&found),
            "{found} of 40 layouts with regions"
        );
    }

    #[test]
    fn find_matches_the_definition_on_the_corpus() {
        let names = [
            "srtm3_N22W160_kauai",
            "srtm3_N57E011_kattegat",
            "scape_crater",
            "ahn3_delft_dsm_50cm",
        ];
        for_each_corpus(&names, |dir, name| {
            let r = load_raw(dir, name);
            assert!(same(&find(&r), &find_reference(&r)), "{name}");
        });
    }
}
