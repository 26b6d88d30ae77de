//! The point-set payloads: the distinct positions (Hilbert order, gaps and multiplicities,
//! range coded) and the sites (levels of doubling size, positions as gaps in the position
//! list, values predicted by the surface of the sites before them), then the explicit
//! values of the points that share a position.
//!
//! The Sibson surface over the sites is one per value column (all on the same positions);
//! the decoder evaluates each at every position (spatial order, on all cores: the value is a
//! pure function of the sites and the position, see `geometry::sibson`).
// Columns index several parallel arrays (values, bounds, lattices, surfaces) at once.
#![allow(clippy::needless_range_loop)]

use crate::container::bytes::{ByteReader, PutLe};
use crate::entropy::range::{Decoder, Encoder, IntModel, UIntModel};
use crate::error::{Error, Result};
use crate::geometry::sibson::{Scratch, Surface};
use crate::methods::sites::level_sizes;
use crate::quant::{code_of, height_of};
use rayon::prelude::*;

const CODING_RANGE: u8 = 0;
/// Most levels a decoder accepts.
pub const MAX_POINT_LEVELS: u32 = 64;

/// The Hilbert index of `(x, y)` on a `2^order` grid.
pub fn hilbert_index(order: u32, x: u32, y: u32) -> u64 {
    let (mut x, mut y) = (x as u64, y as u64);
    let mut d = 0u64;
    let n = 1u64 << order;
    let mut s = n / 2;
    while s > 0 {
        let rx = ((x & s) > 0) as u64;
        let ry = ((y & s) > 0) as u64;
        d += s * s * ((3 * rx) ^ ry);
        // Rotate the quadrant (only the bits below s matter from here on).
        if ry == 0 {
            if rx == 1 {
                x = n - 1 - x;
                y = n - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        s /= 2;
    }
    d
}

/// The position of Hilbert index `d` on a `2^order` grid.
pub fn hilbert_point(order: u32, d: u64) -> (u32, u32) {
    let (mut x, mut y) = (0u64, 0u64);
    let mut t = d;
    let mut s = 1u64;
    let n = 1u64 << order;
    while s < n {
        let rx = 1 & (t / 2);
        let ry = 1 & (t ^ rx);
        if ry == 0 {
            if rx == 1 {
                x = s - 1 - x;
                y = s - 1 - y;
            }
            std::mem::swap(&mut x, &mut y);
        }
        x += s * rx;
        y += s * ry;
        t /= 4;
        s *= 2;
    }
    (x as u32, y as u32)
}

/// The Hilbert curve's order for a grid of `extent`.
pub fn hilbert_order(extent: [u32; 2]) -> u32 {
    let m = extent[0].max(extent[1]).max(2) - 1;
    32 - m.leading_zeros()
}

/// Code distinct positions, sorted by Hilbert index, with their multiplicities.
pub fn write_positions(pos: &[[u32; 2]], mult: &[u32], extent: [u32; 2]) -> Vec<u8> {
    let order = hilbert_order(extent);
    let mut enc = Encoder::new();
    let (mut gaps, mut reps) = (UIntModel::new(), UIntModel::new());
    let mut prev: Option<u64> = None;
    for (p, &m) in pos.iter().zip(mult) {
        let d = hilbert_index(order, p[0], p[1]);
        let gap = match prev {
            None => d,
            Some(q) => d - q - 1,
        };
        gaps.encode(&mut enc, gap);
        reps.encode(&mut enc, (m - 1) as u64);
        prev = Some(d);
    }
    let mut out = vec![CODING_RANGE, 0, 0, 0];
    out.extend_from_slice(&enc.finish());
    out
}

/// Decode `count` positions (and multiplicities summing to `points`) inside `extent`.
pub fn read_positions(
    payload: &[u8],
    count: u64,
    points: u64,
    extent: [u32; 2],
) -> Result<(Vec<[u32; 2]>, Vec<u32>)> {
    let mut r = ByteReader::new(payload, "positions section");
    if r.u8("coding")? != CODING_RANGE {
        return Err(Error::unsupported("positions section coding"));
    }
    if r.take(3, "reserved")? != [0, 0, 0] {
        return Err(r.corrupt("reserved bytes are not zero"));
    }
    let mut dec = Decoder::new(r.take(r.remaining(), "stream")?)?;
    let order = hilbert_order(extent);
    let end = 1u64 << (2 * order);
    let (mut gaps, mut reps) = (UIntModel::new(), UIntModel::new());
    // Grow as decoded: the count was checked against the limits, not trusted for memory.
    let mut pos = Vec::with_capacity(count.min(1 << 20) as usize);
    let mut mult = Vec::with_capacity(count.min(1 << 20) as usize);
    let mut next = 0u64;
    let mut total = 0u64;
    for _ in 0..count {
        let gap = gaps.decode(&mut dec)?;
        let d = next
            .checked_add(gap)
            .filter(|&d| d < end)
            .ok_or_else(|| Error::corrupt("positions section: position past the grid"))?;
        let (x, y) = hilbert_point(order, d);
        if x >= extent[0] || y >= extent[1] {
            return Err(Error::corrupt(
                "positions section: position outside the extent",
            ));
        }
        let m = reps.decode(&mut dec)?;
        if m >= u32::MAX as u64 {
            return Err(Error::corrupt(
                "positions section: a multiplicity over 2^32 − 1",
            ));
        }
        total = total
            .checked_add(m + 1)
            .filter(|&t| t <= points)
            .ok_or_else(|| Error::corrupt("positions section: more points than the header's"))?;
        pos.push([x, y]);
        mult.push((m + 1) as u32);
        next = d + 1;
    }
    if total != points {
        return Err(Error::corrupt(
            "positions section: fewer points than the header's",
        ));
    }
    dec.finish()?;
    Ok((pos, mult))
}

/// A column's height lattice.
#[derive(Clone, Copy, Debug)]
pub struct Lattice {
    /// Step.
    pub step: f64,
    /// Offset.
    pub offset: f64,
}

/// What the sites payload holds besides the positions.
#[derive(Clone, Debug, Default)]
pub struct PointSites {
    /// Levels of (position index, code per column), each sorted by position index.
    pub levels: Vec<Vec<(u32, Vec<i64>)>>,
    /// For each shared position (ascending position index): its members' codes per column.
    pub shared: Vec<Vec<Vec<i64>>>,
}

/// The surfaces of the sites, and the per-column prediction state both ends share.
struct Stream {
    surfs: Vec<Surface>,
    sc: Scratch,
    hint: u32,
    models: Vec<IntModel>,
    prev: Vec<i64>,
}

impl Stream {
    fn new(t: usize) -> Stream {
        Stream {
            surfs: vec![Surface::new(); t],
            sc: Scratch::default(),
            hint: u32::MAX,
            models: vec![IntModel::new(); t],
            prev: vec![0; t],
        }
    }

    fn predict(&mut self, p: [i64; 2], c: usize, lat: &[Lattice]) -> i64 {
        let mut h = self.hint;
        let v = self.surfs[c].eval(p, &mut h, &mut self.sc);
        self.hint = h;
        match v {
            Some(v) => code_of(v, lat[c].step, lat[c].offset),
            None => self.prev[c],
        }
    }

    fn push(&mut self, p: [i64; 2], codes: &[i64], lat: &[Lattice]) -> Result<()> {
        let hint = Some(self.hint).filter(|&h| h != u32::MAX);
        for (c, &code) in codes.iter().enumerate() {
            self.surfs[c].insert_near(p, value_of(code, lat[c])?, hint)?;
            self.prev[c] = code;
        }
        Ok(())
    }
}

fn value_of(code: i64, lat: Lattice) -> Result<f64> {
    let v = height_of(code, lat.step, lat.offset);
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::corrupt("point-sites section: a value out of range"))
    }
}

fn to_i64(p: [u32; 2]) -> [i64; 2] {
    [p[0] as i64, p[1] as i64]
}

/// Code the sites and the shared positions' values. `pos` is the position list,
/// `shared_at` the indices of the positions with more than one point (ascending).
pub fn write_sites(
    s: &PointSites,
    pos: &[[u32; 2]],
    shared_at: &[u32],
    lat: &[Lattice],
) -> Result<Vec<u8>> {
    let t = lat.len();
    let mut st = Stream::new(t);
    let mut streams = Vec::new();
    let mut gaps = UIntModel::new();
    for level in &s.levels {
        let mut enc = Encoder::new();
        let mut prev: Option<u32> = None;
        for (k, codes) in level {
            gaps.encode(&mut enc, prev.map_or(*k, |q| k - q - 1) as u64);
            let p = to_i64(pos[*k as usize]);
            for c in 0..t {
                let pred = st.predict(p, c, lat);
                st.models[c].encode(&mut enc, codes[c] - pred);
            }
            st.push(p, codes, lat)?;
            prev = Some(*k);
        }
        streams.push(enc.finish());
    }
    // The shared positions' members: the first against the final surface, the rest against
    // the member before.
    let mut enc = Encoder::new();
    let mut first = vec![IntModel::new(); t];
    let mut rest = vec![IntModel::new(); t];
    let mut counts = UIntModel::new();
    for (&k, members) in shared_at.iter().zip(&s.shared) {
        counts.encode(&mut enc, members.len() as u64);
        let p = to_i64(pos[k as usize]);
        let preds: Vec<i64> = (0..t).map(|c| st.predict(p, c, lat)).collect();
        for (j, m) in members.iter().enumerate() {
            for c in 0..t {
                if j == 0 {
                    first[c].encode(&mut enc, m[c] - preds[c]);
                } else {
                    rest[c].encode(&mut enc, m[c] - members[j - 1][c]);
                }
            }
        }
    }
    streams.push(enc.finish());
    let mut out = vec![CODING_RANGE, 0, 0, 0];
    out.put_u32(s.levels.len() as u32);
    for (l, b) in s.levels.iter().zip(&streams) {
        out.put_u32(l.len() as u32);
        out.put_u32(b.len() as u32);
    }
    out.put_u32(streams.last().map_or(0, |b| b.len()) as u32);
    for b in &streams {
        out.extend_from_slice(b);
    }
    Ok(out)
}

/// A decoded sites payload.
pub struct DecodedPointSites {
    /// The surfaces over the decoded sites, one per column.
    pub surfaces: Vec<Surface>,
    /// Position index per site, in decode order.
    pub sites: Vec<u32>,
    /// Sites per decoded level.
    pub levels: Vec<usize>,
    /// Value per column per site (decode order).
    pub values: Vec<Vec<f64>>,
    /// Members' values per shared position (ascending position index), `[member][column]`;
    /// empty when only a prefix of the levels was decoded.
    pub shared: Vec<Vec<Vec<f64>>>,
}

/// Decode the sites (`max_levels` levels at most: a prefix of the hierarchy skips the shared
/// values) over the decoded positions.
pub fn read_sites(
    payload: &[u8],
    pos: &[[u32; 2]],
    mult: &[u32],
    lat: &[Lattice],
    max_levels: Option<usize>,
) -> Result<DecodedPointSites> {
    let t = lat.len();
    let mut r = ByteReader::new(payload, "point-sites section");
    if r.u8("coding")? != CODING_RANGE {
        return Err(Error::unsupported("point-sites section coding"));
    }
    if r.take(3, "reserved")? != [0, 0, 0] {
        return Err(r.corrupt("reserved bytes are not zero"));
    }
    let nlev = r.u32("level count")?;
    if nlev > MAX_POINT_LEVELS {
        return Err(r.corrupt(format!(
            "{nlev} levels is over the limit of {MAX_POINT_LEVELS}"
        )));
    }
    let mut lens = Vec::new();
    let mut total = 0u64;
    for _ in 0..nlev {
        let n = r.u32("level size")? as u64;
        let b = r.u32("level bytes")? as usize;
        total += n;
        lens.push((n, b));
    }
    if total > pos.len() as u64 {
        return Err(r.corrupt("more sites than positions"));
    }
    let shared_bytes = r.u32("shared values bytes")? as usize;
    let mut st = Stream::new(t);
    let mut out = DecodedPointSites {
        surfaces: Vec::new(),
        sites: Vec::with_capacity(total as usize),
        levels: Vec::new(),
        values: vec![Vec::with_capacity(total as usize); t],
        shared: Vec::new(),
    };
    let mut is_site = vec![false; pos.len()];
    let mut gaps = UIntModel::new();
    let want = max_levels.unwrap_or(usize::MAX);
    let mut codes = vec![0i64; t];
    for (li, &(n, b)) in lens.iter().enumerate() {
        let bytes = r.take(b, "level stream")?;
        if li >= want {
            continue;
        }
        let mut dec = Decoder::new(bytes)?;
        let mut next = 0u64;
        for _ in 0..n {
            let k = next
                .checked_add(gaps.decode(&mut dec)?)
                .filter(|&k| k < pos.len() as u64)
                .ok_or_else(|| Error::corrupt("point-sites section: site past the positions"))?;
            if is_site[k as usize] {
                return Err(Error::corrupt("point-sites section: a site repeats"));
            }
            is_site[k as usize] = true;
            let p = to_i64(pos[k as usize]);
            for c in 0..t {
                let pred = st.predict(p, c, lat);
                codes[c] = pred
                    .checked_add(st.models[c].decode(&mut dec)?)
                    .ok_or_else(|| Error::corrupt("point-sites section: code overflow"))?;
            }
            st.push(p, &codes, lat)?;
            out.sites.push(k as u32);
            for c in 0..t {
                out.values[c].push(value_of(codes[c], lat[c])?);
            }
            next = k + 1;
        }
        dec.finish()?;
        out.levels.push(n as usize);
    }
    let sb = r.take(shared_bytes, "shared values")?;
    r.finish()?;
    if !pos.is_empty() && out.sites.is_empty() {
        return Err(Error::corrupt("point-sites section: no sites"));
    }
    if out.levels.len() == lens.len() {
        let mut dec = Decoder::new(sb)?;
        let mut first = vec![IntModel::new(); t];
        let mut rest = vec![IntModel::new(); t];
        let mut counts = UIntModel::new();
        for (k, &m) in mult.iter().enumerate().filter(|(_, m)| **m > 1) {
            if counts.decode(&mut dec)? != m as u64 {
                return Err(Error::corrupt("point-sites section: shared count mismatch"));
            }
            let p = to_i64(pos[k]);
            let preds: Vec<i64> = (0..t).map(|c| st.predict(p, c, lat)).collect();
            let mut members: Vec<Vec<f64>> = Vec::with_capacity(m as usize);
            let mut prev = preds.clone();
            for j in 0..m {
                let mut row = Vec::with_capacity(t);
                for c in 0..t {
                    let d = if j == 0 {
                        first[c].decode(&mut dec)?
                    } else {
                        rest[c].decode(&mut dec)?
                    };
                    let code = prev[c]
                        .checked_add(d)
                        .ok_or_else(|| Error::corrupt("point-sites section: code overflow"))?;
                    prev[c] = code;
                    row.push(value_of(code, lat[c])?);
                }
                members.push(row);
            }
            out.shared.push(members);
        }
        dec.finish()?;
    }
    out.surfaces = st.surfs;
    for s in &mut out.surfaces {
        s.compact();
    }
    Ok(out)
}

/// Evaluate each surface at every position (in the positions' spatial order, on all cores).
pub fn eval_at(surfaces: &[Surface], pos: &[[u32; 2]]) -> Result<Vec<Vec<f64>>> {
    const CHUNK: usize = 4096;
    surfaces
        .iter()
        .map(|s| {
            let parts: Vec<Result<Vec<f64>>> = pos
                .par_chunks(CHUNK)
                .map(|chunk| {
                    let mut sc = Scratch::default();
                    let mut hint = None;
                    chunk
                        .iter()
                        .map(|&p| {
                            s.eval_seq(to_i64(p), &mut hint, &mut sc).ok_or_else(|| {
                                Error::corrupt("a position lies outside the sites' hull")
                            })
                        })
                        .collect()
                })
                .collect();
            let mut v = Vec::with_capacity(pos.len());
            for p in parts {
                v.extend(p?);
            }
            Ok(v)
        })
        .collect()
}

/// Split importance-ordered sites into levels (the first holds the hull), each sorted by
/// position index.
pub fn into_levels(sites: &[(u32, Vec<i64>)], hull: usize) -> Vec<Vec<(u32, Vec<i64>)>> {
    let mut levels = Vec::new();
    let mut at = 0;
    for n in level_sizes(sites.len(), hull) {
        let mut l = sites[at..at + n].to_vec();
        l.sort_unstable_by_key(|s| s.0);
        levels.push(l);
        at += n;
    }
    levels
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hilbert_round_trips() {
        for order in [1, 3, 8] {
            let n = 1u32 << order;
            let mut seen = vec![false; (n * n) as usize];
            for x in 0..n {
                for y in 0..n {
                    let d = hilbert_index(order, x, y);
                    assert_eq!(hilbert_point(order, d), (x, y));
                    assert!(!seen[d as usize]);
                    seen[d as usize] = true;
                }
            }
        }
        let o = hilbert_order([1 << 24, 3]);
        let d = hilbert_index(o, (1 << 24) - 1, 2);
        assert_eq!(hilbert_point(o, d), ((1 << 24) - 1, 2));
    }

    #[test]
    fn positions_round_trip() {
        let extent = [1000, 700];
        let order = hilbert_order(extent);
        let mut pos: Vec<[u32; 2]> = (0..500u32)
            .map(|i| [(i * 37) % 1000, (i * 91) % 700])
            .collect();
        pos.sort_by_key(|p| hilbert_index(order, p[0], p[1]));
        pos.dedup();
        let mult: Vec<u32> = (0..pos.len() as u32)
            .map(|i| 1 + (i % 7 == 0) as u32)
            .collect();
        let total = mult.iter().map(|&m| m as u64).sum();
        let b = write_positions(&pos, &mult, extent);
        let (p2, m2) = read_positions(&b, pos.len() as u64, total, extent).unwrap();
        assert!(read_positions(&b, pos.len() as u64, total + 1, extent).is_err());
        assert_eq!((p2, m2), (pos, mult));
    }
}
