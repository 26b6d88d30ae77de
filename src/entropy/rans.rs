//! Static rANS over small alphabets (the residual layer's fast coding, spec/FORMAT.md
//! "Fast coding"): frequency tables of 12-bit precision sent ahead of the data, one 32-bit
//! state renormalised in 16-bit words, and a plain little-endian bit stream beside it for
//! raw bits.
//!
//! Hand-written rather than taken from a crate (constriction, the ryg_rans ports): the file
//! format pins every byte of the stream (golden files decode forever), which no crate
//! promises of its encoder's output across versions, and the decoder's inner step is five
//! lines. The construction is Duda's rANS as in ryg_rans (state in [2^16, 2^32), 16-bit
//! renormalisation) with the decode table of one packed entry per slot (zstd's FSE and
//! JPEG XL use the same idea).

use crate::error::{Error, Result};

/// Frequencies sum to 2^PREC.
pub const PREC: u32 = 12;
/// 2^PREC.
pub const TOTAL: u32 = 1 << PREC;
/// The state's lower bound; a stream starts (encoder) and ends (decoder) in this state.
pub const LOW: u32 = 1 << 16;

/// Frequencies (summing to [`TOTAL`]) from counts; every symbol with a count gets at
/// least one slot. All counts 0 give the one-symbol table `[TOTAL]`. Trailing zero
/// frequencies are cut, so the last frequency is never 0.
pub fn normalize(counts: &[u64]) -> Vec<u32> {
    let n: u64 = counts.iter().sum();
    let last = counts.iter().rposition(|&c| c > 0);
    let Some(last) = last else {
        return vec![TOTAL];
    };
    let mut f: Vec<u32> = counts[..=last]
        .iter()
        .map(|&c| {
            if c == 0 {
                0
            } else {
                (((c as u128 * TOTAL as u128 + n as u128 / 2) / n as u128) as u32).max(1)
            }
        })
        .collect();
    // Give or take the difference on the largest frequencies (the smallest relative loss).
    let mut sum: i64 = f.iter().map(|&v| v as i64).sum();
    while sum != TOTAL as i64 {
        let (k, _) = f
            .iter()
            .enumerate()
            .max_by_key(|&(i, &v)| (v, std::cmp::Reverse(i)))
            .expect("one symbol at least");
        if sum < TOTAL as i64 {
            f[k] += (TOTAL as i64 - sum) as u32;
            sum = TOTAL as i64;
        } else {
            // Take from the largest, keeping it ≥ 1 (and ≥ its share).
            let take = (sum - TOTAL as i64).min(f[k] as i64 - 1).max(0);
            if take == 0 {
                // Only 1s left above: impossible with ≤ TOTAL symbols and sum > TOTAL.
                unreachable!("normalize: {} symbols cannot sum to {TOTAL}", f.len());
            }
            f[k] -= take as u32;
            sum -= take;
        }
    }
    // The last symbol counted, so its frequency is ≥ 1 still.
    debug_assert!(*f.last().expect("nonempty") > 0);
    f
}

/// What a table costs to store, in bits (as [`write_table`] writes it).
pub fn table_bits(freqs: &[u32]) -> u64 {
    7 + freqs[..freqs.len() - 1]
        .iter()
        .map(|&f| gamma_bits(f as u64 + 1))
        .sum::<u64>()
}

fn gamma_bits(v: u64) -> u64 {
    2 * (63 - v.leading_zeros() as u64) + 1
}

/// Store a table: its alphabet size n in 7 bits, then the first n − 1 frequencies as Elias
/// gamma codes of f + 1 (the last is what the others leave of [`TOTAL`]).
pub fn write_table(w: &mut BitWriter, freqs: &[u32]) {
    w.put(freqs.len() as u64, 7);
    for &f in &freqs[..freqs.len() - 1] {
        w.gamma(f as u64 + 1);
    }
}

/// Read a table written by [`write_table`], checked: n in 1 ..= `max_alphabet`, the sum of
/// the first n − 1 below [`TOTAL`].
pub fn read_table(r: &mut BitReader, max_alphabet: usize) -> Result<Vec<u32>> {
    let n = r.get(7)? as usize;
    if n == 0 || n > max_alphabet {
        return Err(r.corrupt(format!("a table of {n} symbols (1 ..= {max_alphabet})")));
    }
    let mut f = Vec::with_capacity(n);
    let mut sum = 0u64;
    for _ in 0..n - 1 {
        let v = r.gamma()? - 1;
        sum += v;
        if sum >= TOTAL as u64 {
            return Err(r.corrupt("a table's frequencies exceed 4096"));
        }
        f.push(v as u32);
    }
    f.push(TOTAL - sum as u32);
    Ok(f)
}

/// The encoder's view of one table: per symbol its frequency and start.
#[derive(Clone, Debug)]
pub struct EncTable {
    freq: Vec<u32>,
    cum: Vec<u32>,
}

impl EncTable {
    pub fn new(freqs: &[u32]) -> EncTable {
        let mut cum = Vec::with_capacity(freqs.len());
        let mut c = 0;
        for &f in freqs {
            cum.push(c);
            c += f;
        }
        EncTable {
            freq: freqs.to_vec(),
            cum,
        }
    }
}

/// Decode tables of several contexts, one packed entry per slot: symbol (bits 25..32),
/// frequency (bits 12..25) and the slot's offset within its symbol (bits 0..12).
pub struct DecTables {
    entries: Vec<u32>,
}

impl DecTables {
    /// Tables in the order of `tables`; table k starts at slot k·[`TOTAL`].
    pub fn new(tables: &[Vec<u32>]) -> DecTables {
        let mut entries = Vec::with_capacity(tables.len() * TOTAL as usize);
        for t in tables {
            for (s, &f) in t.iter().enumerate() {
                for o in 0..f {
                    entries.push(((s as u32) << 25) | (f << 12) | o);
                }
            }
        }
        DecTables { entries }
    }

    /// Table k's slots (k below the number of tables).
    pub fn table(&self, k: usize) -> &[u32; TOTAL as usize] {
        self.entries[k * TOTAL as usize..(k + 1) * TOTAL as usize]
            .try_into()
            .expect("a whole table")
    }
}

/// Encodes one stream. Symbols are given in stream order; [`StreamEncoder::finish`] codes
/// them (rANS runs backwards) into the bytes the decoder reads forwards.
pub struct StreamEncoder;

impl StreamEncoder {
    /// The rANS bytes of `symbols`, each `(table, symbol)` with a nonzero frequency: the
    /// final state (u32 LE) then the renormalisation words (u16 LE) in decode order.
    pub fn encode(
        tables: &[EncTable],
        symbols: impl DoubleEndedIterator<Item = (usize, u8)>,
    ) -> Vec<u8> {
        let mut words: Vec<u16> = Vec::new();
        let mut x: u32 = LOW;
        for (t, s) in symbols.rev() {
            let t = &tables[t];
            let f = t.freq[s as usize];
            debug_assert!(f > 0, "symbol {s} has no frequency");
            // Renormalise so that the coded state stays below 2^32 (in u64: a symbol of
            // frequency 2^PREC has the bound 2^32 itself, and never renormalises).
            let x_max = (f as u64) << (32 - PREC);
            if x as u64 >= x_max {
                words.push(x as u16);
                x >>= 16;
            }
            x = ((x / f) << PREC) + (x % f) + t.cum[s as usize];
        }
        let mut out = Vec::with_capacity(4 + 2 * words.len());
        out.extend_from_slice(&x.to_le_bytes());
        for w in words.iter().rev() {
            out.extend_from_slice(&w.to_le_bytes());
        }
        out
    }
}

/// Decodes one stream's symbols.
pub struct StreamDecoder<'a> {
    x: u32,
    bytes: &'a [u8],
    pos: usize,
    tables: &'a [u32],
}

impl<'a> StreamDecoder<'a> {
    pub fn new(bytes: &'a [u8], tables: &'a DecTables) -> Result<StreamDecoder<'a>> {
        let Some(first) = bytes.get(..4) else {
            return Err(corrupt("an entropy stream is shorter than its state"));
        };
        let x = u32::from_le_bytes(first.try_into().expect("4 bytes"));
        if x < LOW {
            return Err(corrupt("an entropy stream starts below its lowest state"));
        }
        Ok(StreamDecoder {
            x,
            bytes,
            pos: 4,
            tables: &tables.entries,
        })
    }

    /// The next symbol, from the table starting at slot `base` (k·[`TOTAL`]).
    #[inline(always)]
    pub fn symbol(&mut self, base: usize) -> Result<u8> {
        let e = self.tables[base + (self.x & (TOTAL - 1)) as usize];
        self.x = step(self.x, e, self.bytes, &mut self.pos)?;
        Ok((e >> 25) as u8)
    }

    /// Check the stream's end: every word read and the state back where the encoder began.
    pub fn finish(&self) -> Result<()> {
        if self.pos != self.bytes.len() || self.x != LOW {
            return Err(corrupt(
                "an entropy stream does not end where its symbols do",
            ));
        }
        Ok(())
    }
}

/// Interleaved states of the lane coding's streams (spec/FORMAT.md, "Lane coding"): symbol
/// k of a pass row is coded in state k mod 4, all states sharing one word stream (ryg_rans'
/// interleaving, as zstd's huff0 and JPEG XL's ANS use several streams or states), so the
/// decoder's steps for consecutive symbols overlap in the processor.
pub const STATES: usize = 4;

/// Encodes one stream of interleaved states.
pub struct LanesEncoder;

impl LanesEncoder {
    /// The bytes of `symbols`, each `(table, symbol, state)` with a nonzero frequency and a
    /// state below `states` (1 ..= [`STATES`]): the final states (u32 LE, state 0 first),
    /// then the renormalisation words (u16 LE) in decode order.
    pub fn encode(tables: &[EncTable], symbols: &[(u16, u8, u8)], states: usize) -> Vec<u8> {
        let mut words: Vec<u16> = Vec::with_capacity(symbols.len() / 2);
        let mut xs = [LOW; STATES];
        for &(t, s, l) in symbols.iter().rev() {
            let t = &tables[t as usize];
            let f = t.freq[s as usize];
            debug_assert!(f > 0, "symbol {s} has no frequency");
            let x = &mut xs[l as usize];
            let x_max = (f as u64) << (32 - PREC);
            if *x as u64 >= x_max {
                words.push(*x as u16);
                *x >>= 16;
            }
            *x = ((*x / f) << PREC) + (*x % f) + t.cum[s as usize];
        }
        let mut out = Vec::with_capacity(4 * states + 2 * words.len());
        for x in &xs[..states] {
            out.extend_from_slice(&x.to_le_bytes());
        }
        debug_assert!(
            xs[states..].iter().all(|&x| x == LOW),
            "a symbol of an unused state"
        );
        for w in words.iter().rev() {
            out.extend_from_slice(&w.to_le_bytes());
        }
        out
    }
}

/// Decodes one stream of interleaved states.
pub struct LanesDecoder<'a> {
    x: [u32; STATES],
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> LanesDecoder<'a> {
    /// A stream of `states` interleaved states (1 ..= [`STATES`]; the others stay unused).
    pub fn new(bytes: &'a [u8], states: usize) -> Result<LanesDecoder<'a>> {
        let Some(first) = bytes.get(..4 * states) else {
            return Err(corrupt("an entropy stream is shorter than its states"));
        };
        let mut x = [LOW; STATES];
        for (x, b) in x.iter_mut().zip(first.chunks_exact(4)) {
            *x = u32::from_le_bytes(b.try_into().expect("4 bytes"));
            if *x < LOW {
                return Err(corrupt("an entropy stream starts below its lowest state"));
            }
        }
        Ok(LanesDecoder {
            x,
            bytes,
            pos: 4 * states,
        })
    }

    /// The next symbol of state `lane` (< [`STATES`]) from `table` (one of
    /// [`DecTables::table`]).
    #[inline(always)]
    pub fn symbol(&mut self, lane: usize, table: &[u32; TOTAL as usize]) -> Result<u32> {
        let e = table[(self.x[lane] & (TOTAL - 1)) as usize];
        self.x[lane] = step(self.x[lane], e, self.bytes, &mut self.pos)?;
        Ok(e >> 25)
    }

    /// Check the stream's end: every word read and every state back where the encoder
    /// began.
    pub fn finish(&self) -> Result<()> {
        if self.pos != self.bytes.len() || self.x != [LOW; STATES] {
            return Err(corrupt(
                "an entropy stream does not end where its symbols do",
            ));
        }
        Ok(())
    }
}

/// One decoding step of state `x` whose slot's packed entry is `e`: the next state, with a
/// word read from `bytes` at `pos` when it falls below [`LOW`].
#[inline(always)]
fn step(x: u32, e: u32, bytes: &[u8], pos: &mut usize) -> Result<u32> {
    let mut x = ((e >> 12) & 0x1fff) * (x >> PREC) + (e & 0xfff);
    if x < LOW {
        let Some(w) = bytes.get(*pos..*pos + 2) else {
            return Err(corrupt("an entropy stream ends early"));
        };
        x = (x << 16) | u16::from_le_bytes([w[0], w[1]]) as u32;
        *pos += 2;
    }
    Ok(x)
}

#[cold]
fn corrupt(msg: &str) -> Error {
    Error::corrupt(format!("residual section: {msg}"))
}

/// Bits written least significant first into bytes (the raw bits beside a rANS stream, and
/// the tables).
#[derive(Default)]
pub struct BitWriter {
    out: Vec<u8>,
    acc: u64,
    n: u32,
}

impl BitWriter {
    /// Append the low `bits` bits of `v` (`bits` ≤ 56).
    #[inline]
    pub fn put(&mut self, v: u64, bits: u32) {
        debug_assert!(bits <= 56 && (bits == 64 || v >> bits == 0));
        self.acc |= v << self.n;
        self.n += bits;
        while self.n >= 8 {
            self.out.push(self.acc as u8);
            self.acc >>= 8;
            self.n -= 8;
        }
    }

    /// Elias gamma code of v ≥ 1: ⌊log2 v⌋ ones, a zero, then the ⌊log2 v⌋ low bits of v.
    pub fn gamma(&mut self, v: u64) {
        let e = 63 - v.leading_zeros();
        for _ in 0..e {
            self.put(1, 1);
        }
        self.put(0, 1);
        self.put(v & ((1 << e) - 1), e);
    }

    /// The bytes, the last one padded with zero bits.
    pub fn finish(mut self) -> Vec<u8> {
        if self.n > 0 {
            self.out.push(self.acc as u8);
        }
        self.out
    }
}

/// Reads what [`BitWriter`] wrote; reading past the end is corrupt data.
pub struct BitReader<'a> {
    bytes: &'a [u8],
    pos: usize,
    acc: u64,
    n: u32,
    what: &'static str,
}

impl<'a> BitReader<'a> {
    pub fn new(bytes: &'a [u8], what: &'static str) -> BitReader<'a> {
        BitReader {
            bytes,
            pos: 0,
            acc: 0,
            n: 0,
            what,
        }
    }

    /// The next `bits` bits (≤ 56).
    #[inline(always)]
    pub fn get(&mut self, bits: u32) -> Result<u64> {
        if self.n < bits {
            self.refill();
            if self.n < bits {
                return Err(self.corrupt("its bits end early"));
            }
        }
        let v = self.acc & ((1u64 << bits) - 1);
        self.acc >>= bits;
        self.n -= bits;
        Ok(v)
    }

    #[inline(always)]
    fn refill(&mut self) {
        if let Some(b) = self.bytes.get(self.pos..self.pos + 8) {
            // Take as many whole bytes as fit.
            let k = (63 - self.n) / 8;
            let word = u64::from_le_bytes(b.try_into().expect("8 bytes"));
            let take = if k == 8 {
                word
            } else {
                word & ((1u64 << (8 * k)) - 1)
            };
            self.acc |= take << self.n;
            self.n += 8 * k;
            self.pos += k as usize;
        } else {
            while self.n <= 56 && self.pos < self.bytes.len() {
                self.acc |= (self.bytes[self.pos] as u64) << self.n;
                self.n += 8;
                self.pos += 1;
            }
        }
    }

    /// An Elias gamma code (at most 32 leading ones).
    pub fn gamma(&mut self) -> Result<u64> {
        let mut e = 0;
        while self.get(1)? == 1 {
            e += 1;
            if e > 32 {
                return Err(self.corrupt("a gamma code is too long"));
            }
        }
        Ok((1 << e) | self.get(e)?)
    }

    /// Check the end: every byte read, and only zero padding (fewer than 8 bits) left.
    pub fn finish(&mut self) -> Result<()> {
        self.refill();
        if self.pos != self.bytes.len() || self.n >= 8 || self.acc != 0 {
            return Err(self.corrupt("it does not end where its bits do"));
        }
        Ok(())
    }

    #[cold]
    pub fn corrupt(&self, msg: impl std::fmt::Display) -> Error {
        Error::corrupt(format!("residual section: {}: {msg}", self.what))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalize_sums_and_keeps_every_counted_symbol() {
        for counts in [
            vec![1u64],
            vec![0, 0, 5],
            vec![1_000_000, 1, 0, 1, 3],
            (0..90).map(|k| 1 + k * k).collect(),
            vec![0; 4],
        ] {
            let f = normalize(&counts);
            assert_eq!(f.iter().sum::<u32>(), TOTAL, "{counts:?}");
            assert!(*f.last().unwrap() > 0);
            if counts.iter().all(|&c| c == 0) {
                assert_eq!(f, [TOTAL]);
                continue;
            }
            for (c, f) in counts.iter().zip(&f) {
                assert_eq!(*c > 0, *f > 0, "{counts:?} → {f:?}");
            }
        }
    }

    #[test]
    fn streams_round_trip_and_end_exactly() {
        let t0 = normalize(&[900, 50, 30, 10, 5, 4, 1]);
        let t1 = normalize(&[1, 1, 1]);
        let t2 = normalize(&[7]);
        assert_eq!(t2, [TOTAL]);
        let enc = [EncTable::new(&t0), EncTable::new(&t1), EncTable::new(&t2)];
        let dec = DecTables::new(&[t0.clone(), t1.clone(), t2.clone()]);
        let mut syms = Vec::new();
        let mut rng = crate::testutil::Rng(12345);
        for i in 0..20000 {
            let s = rng.next();
            let t = i % 3;
            let n = [t0.len(), t1.len(), 1][t];
            let mut sym = ((s >> 33) % n as u64) as u8;
            if t == 0 && (s >> 20) % 4 != 0 {
                sym = 0;
            }
            syms.push((t, sym));
        }
        let bytes = StreamEncoder::encode(&enc, syms.iter().copied());
        let mut d = StreamDecoder::new(&bytes, &dec).unwrap();
        for &(t, sym) in &syms {
            assert_eq!(d.symbol(t * TOTAL as usize).unwrap(), sym);
        }
        d.finish().unwrap();
        // Every proper prefix fails: early in the stream or at its end check.
        for cut in 0..bytes.len() {
            let r = StreamDecoder::new(&bytes[..cut], &dec).and_then(|mut d| {
                for &(t, _) in &syms {
                    d.symbol(t * TOTAL as usize)?;
                }
                d.finish()
            });
            assert!(r.is_err(), "prefix of {cut} bytes decoded");
        }
    }

    #[test]
    fn bits_and_tables_round_trip() {
        let mut w = BitWriter::default();
        let tables = [
            normalize(&[3, 0, 9, 1]),
            normalize(&[1]),
            normalize(&[0, 0, 0, 2]),
        ];
        for t in &tables {
            write_table(&mut w, t);
        }
        w.put(0x0012_3456_789a, 40);
        w.put(1, 1);
        let bytes = w.finish();
        let mut r = BitReader::new(&bytes, "tables");
        for t in &tables {
            assert_eq!(&read_table(&mut r, 90).unwrap(), t);
        }
        assert_eq!(r.get(40).unwrap(), 0x0012_3456_789a);
        assert_eq!(r.get(1).unwrap(), 1);
        r.finish().unwrap();
        // Cut short, something fails to read.
        let mut r = BitReader::new(&bytes[..bytes.len() - 1], "tables");
        let res = (|| -> Result<()> {
            for _ in &tables {
                read_table(&mut r, 90)?;
            }
            r.get(40)?;
            r.get(1)?;
            Ok(())
        })();
        assert!(res.is_err());
    }
}
