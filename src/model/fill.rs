//! Filling the invalid samples of a grid before an encoder transforms it (FIS, Haar).

/// Fill the invalid samples (per `mask`) of a `w`-wide row-major grid in place: a gap
/// between two valid samples `a` and `b` of a row gets `between(v[a], v[b], i − a, b − a)`
/// at each index i, a gap at a row's start or end the nearest valid value of the row, and a
/// row without valid samples a copy of the nearest row that has one. Returns false (and
/// changes nothing) when no sample is valid. Encoders only: decoders write the nodata fill.
pub(crate) fn fill_invalid<T: Copy>(
    v: &mut [T],
    mask: &[bool],
    w: usize,
    h: usize,
    between: impl Fn(T, T, usize, usize) -> T,
) -> bool {
    let mut has_valid = vec![false; h];
    for y in 0..h {
        let row = &mut v[y * w..][..w];
        let m = &mask[y * w..][..w];
        let mut prev: Option<usize> = None;
        let mut x = 0;
        while x < w {
            if m[x] {
                prev = Some(x);
                x += 1;
                continue;
            }
            let start = x;
            while x < w && !m[x] {
                x += 1;
            }
            match (prev, (x < w).then_some(x)) {
                (Some(a), Some(b)) => {
                    let (va, vb) = (row[a], row[b]);
                    for (i, c) in row.iter_mut().enumerate().take(b).skip(start) {
                        *c = between(va, vb, i - a, b - a);
                    }
                }
                (Some(a), None) => {
                    let va = row[a];
                    row[start..x].iter_mut().for_each(|c| *c = va);
                }
                (None, Some(b)) => {
                    let vb = row[b];
                    row[start..b].iter_mut().for_each(|c| *c = vb);
                }
                (None, None) => {}
            }
        }
        has_valid[y] = prev.is_some();
    }
    let Some(first) = has_valid.iter().position(|&b| b) else {
        return false;
    };
    let mut last = first;
    for (y, &valid) in has_valid.iter().enumerate() {
        if valid {
            last = y;
        } else {
            let src = if y < first { first } else { last };
            v.copy_within(src * w..src * w + w, y * w);
        }
    }
    true
}
