//! Flat regions: connected areas of one exact value (sea, lakes, reservoirs, building pads)
//! that every method must decode to exactly that value. Finding them (encoder) and
//! labelling a flat-sample bitmap into regions (encoder and decoder alike).

use super::Raster;

/// Regions smaller than this many samples are not worth a section entry (a value and its
/// border's run lengths cost more than what the method spends on them).
pub const MIN_REGION: usize = 1024;

/// Label the 4-connected components of `flat` (a `w`-wide bitmap) in raster order: the
/// component holding the first flat sample is 1, the next one not yet labelled 2, and so
/// on; 0 marks samples that are not flat. Returns the labels and the component count.
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

/// The flat regions of `r`: per sample its region's value, NaN outside every region; `None`
/// when there is none. Regions are 4-connected runs of one exact value among valid samples,
/// of at least [`MIN_REGION`] samples. Where two regions of different values touch, the
/// touching samples on both sides are left out (the rest stays flat, even a piece that this
/// cuts off), so that [`label`] of the result gives regions of one value each to a decoder
/// that sees only the bitmap.
pub(crate) fn find(r: &Raster) -> Option<Vec<f64>> {
    let (w, n) = (r.width, r.len());
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
    let big = |i: usize| comp[i] != u32::MAX && sizes[comp[i] as usize] >= MIN_REGION;
    if !(0..n).any(big) {
        return None;
    }
    // Keep big components, minus samples touching another big component.
    let mut flat: Vec<bool> = (0..n).map(big).collect();
    let mut drop = vec![false; n];
    for i in 0..n {
        if !flat[i] {
            continue;
        }
        let x = i % w;
        for j in [(x + 1 < w).then(|| i + 1), (i + w < n).then(|| i + w)]
            .into_iter()
            .flatten()
        {
            if flat[j] && comp[j] != comp[i] {
                drop[i] = true;
                drop[j] = true;
            }
        }
    }
    for i in 0..n {
        flat[i] &= !drop[i];
    }
    let mut any = false;
    let out: Vec<f64> = (0..n)
        .map(|i| {
            if flat[i] {
                any = true;
                r.data[i]
            } else {
                f64::NAN
            }
        })
        .collect();
    any.then_some(out)
}
