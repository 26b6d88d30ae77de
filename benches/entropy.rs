//! Benchmarks vtz's range coder against the `arithmetic-coding` crate on binary and integer streams.
//!
//! Streams: 1 M binary decisions with p(1) = 0.05 and 0.3, and 200 k Laplacian integers
//! (scale 3 and 40, like quantized prediction residuals). Both coders use adaptive models:
//! vtz one [`Bit`] for the decisions and an [`IntModel`] for the integers; the crate a
//! frequency-count model over the alphabet (2 symbols, or min..=max of the stream) plus the
//! end-of-stream symbol it needs, kept in a Fenwick tree like the crate's `fenwick-model`
//! examples (counts +1 per symbol, halved when the total reaches 2^20).
//!
//! Run: `cargo bench --bench entropy -- --warm-up-time 1 --measurement-time 3`. Before the
//! criterion groups it prints a table of sizes against the zeroth-order entropy and of
//! speeds (best of 3 runs).

use arithmetic_coding::Model;
use bitstream_io::{BigEndian, BitReader, BitWrite, BitWriter};
use criterion::{Criterion, Throughput, criterion_group};
use std::collections::HashMap;
use std::convert::Infallible;
use std::hash::Hash;
use std::hint::black_box;
use std::ops::Range;
use std::time::Instant;
use vtz::internals::range::{Bit, Decoder, Encoder, IntModel};

#[path = "../tests/common/mod.rs"]
mod common;

use common::Rng;

// ---------------------------------------------------------------- test data

fn binary_stream(p: f64, n: usize, seed: u64) -> Vec<bool> {
    let mut rng = Rng(seed);
    (0..n).map(|_| rng.unit() < p).collect()
}

/// Rounded Laplacian samples with the given scale (mean |v| ≈ scale).
fn laplacian_stream(scale: f64, n: usize, seed: u64) -> Vec<i64> {
    let mut rng = Rng(seed);
    (0..n)
        .map(|_| {
            let m = (-(1.0 - rng.unit()).ln() * scale).round() as i64;
            if rng.next() & 1 == 0 { m } else { -m }
        })
        .collect()
}

/// Zeroth-order empirical entropy, bits per symbol.
fn entropy<T: Hash + Eq>(symbols: &[T]) -> f64 {
    let mut counts: HashMap<&T, usize> = HashMap::new();
    for s in symbols {
        *counts.entry(s).or_default() += 1;
    }
    let n = symbols.len() as f64;
    counts
        .values()
        .map(|&c| -(c as f64 / n) * (c as f64 / n).log2())
        .sum()
}

// ---------------------------------------------------------------- vtz

fn vtz_encode_bits(bits: &[bool]) -> Vec<u8> {
    let mut enc = Encoder::with_capacity(bits.len() / 8);
    let mut ctx = Bit::default();
    for &b in bits {
        enc.encode(&mut ctx, b);
    }
    enc.finish()
}

fn vtz_decode_bits(bytes: &[u8], n: usize) -> Vec<bool> {
    let mut dec = Decoder::new(bytes).unwrap();
    let mut ctx = Bit::default();
    let out = (0..n).map(|_| dec.decode(&mut ctx)).collect();
    dec.finish().unwrap();
    out
}

fn vtz_encode_ints(values: &[i64]) -> Vec<u8> {
    let mut enc = Encoder::with_capacity(values.len());
    let mut model = IntModel::new();
    for &v in values {
        model.encode(&mut enc, v);
    }
    enc.finish()
}

fn vtz_decode_ints(bytes: &[u8], n: usize) -> Vec<i64> {
    let mut dec = Decoder::new(bytes).unwrap();
    let mut model = IntModel::new();
    let out = (0..n).map(|_| model.decode(&mut dec).unwrap()).collect();
    dec.finish().unwrap();
    out
}

// ---------------------------------------------------------------- arithmetic-coding

/// Adaptive frequency model over symbols `0..n` plus end-of-stream (slot 0), with
/// cumulative counts in a Fenwick tree.
#[derive(Clone)]
struct FreqModel {
    counts: Vec<u64>,
    /// Fenwick tree over `counts` (1-based: `tree[i]` covers slots `i - lowbit(i)..i`).
    tree: Vec<u64>,
    total: u64,
    max_total: u64,
}

impl FreqModel {
    fn new(symbols: usize) -> Self {
        let mut m = FreqModel {
            counts: vec![1; symbols + 1],
            tree: Vec::new(),
            total: 0,
            max_total: 1 << 20,
        };
        m.rebuild();
        m
    }

    fn rebuild(&mut self) {
        let n = self.counts.len();
        self.tree = vec![0; n + 1];
        for i in 1..=n {
            self.tree[i] += self.counts[i - 1];
            let parent = i + (i & i.wrapping_neg());
            if parent <= n {
                self.tree[parent] += self.tree[i];
            }
        }
        self.total = self.counts.iter().sum();
    }

    /// Sum of the counts of slots `0..slot`.
    fn prefix(&self, slot: usize) -> u64 {
        let (mut i, mut s) = (slot, 0);
        while i > 0 {
            s += self.tree[i];
            i &= i - 1;
        }
        s
    }

    fn slot(symbol: Option<&usize>) -> usize {
        symbol.map_or(0, |&s| s + 1)
    }
}

impl Model for FreqModel {
    type B = u64;
    type Symbol = usize;
    type ValueError = Infallible;

    fn probability(&self, symbol: Option<&usize>) -> Result<Range<u64>, Infallible> {
        let slot = Self::slot(symbol);
        let lo = self.prefix(slot);
        Ok(lo..lo + self.counts[slot])
    }

    fn symbol(&self, value: u64) -> Option<usize> {
        // Largest slot whose prefix sum is <= value (Fenwick descent).
        let n = self.counts.len();
        let (mut pos, mut rem) = (0usize, value);
        let mut step = n.next_power_of_two();
        while step > 0 {
            if pos + step <= n && self.tree[pos + step] <= rem {
                pos += step;
                rem -= self.tree[pos];
            }
            step >>= 1;
        }
        pos.checked_sub(1)
    }

    fn max_denominator(&self) -> u64 {
        self.max_total
    }

    fn denominator(&self) -> u64 {
        self.total
    }

    fn update(&mut self, symbol: Option<&usize>) {
        if self.total >= self.max_total {
            for c in &mut self.counts {
                *c = (*c).div_ceil(2);
            }
            self.rebuild();
        }
        let slot = Self::slot(symbol);
        self.counts[slot] += 1;
        self.total += 1;
        let mut i = slot + 1;
        while i < self.tree.len() {
            self.tree[i] += 1;
            i += i & i.wrapping_neg();
        }
    }
}

fn ac_encode(symbols: &[usize], alphabet: usize) -> Vec<u8> {
    let mut w = BitWriter::endian(Vec::with_capacity(symbols.len() / 4), BigEndian);
    arithmetic_coding::Encoder::new(FreqModel::new(alphabet), &mut w)
        .encode_all(symbols.iter().copied())
        .unwrap();
    w.byte_align().unwrap();
    w.into_writer()
}

fn ac_decode(bytes: &[u8], alphabet: usize) -> Vec<usize> {
    let mut dec = arithmetic_coding::Decoder::new(
        FreqModel::new(alphabet),
        BitReader::endian(bytes, BigEndian),
    );
    dec.decode_all().map(Result::unwrap).collect()
}

// ---------------------------------------------------------------- streams

/// One test stream, in the form each coder takes.
struct Stream {
    name: String,
    /// Binary decisions (for vtz's bare coder) or integers (for its IntModel).
    bits: Option<Vec<bool>>,
    ints: Option<Vec<i64>>,
    /// The same stream as alphabet indices for arithmetic-coding.
    symbols: Vec<usize>,
    alphabet: usize,
    entropy: f64,
}

impl Stream {
    fn binary(p: f64, n: usize, seed: u64) -> Self {
        let bits = binary_stream(p, n, seed);
        Stream {
            name: format!("binary p={p}"),
            symbols: bits.iter().map(|&b| b as usize).collect(),
            alphabet: 2,
            entropy: entropy(&bits),
            bits: Some(bits),
            ints: None,
        }
    }

    fn laplacian(scale: f64, n: usize, seed: u64) -> Self {
        let ints = laplacian_stream(scale, n, seed);
        let min = *ints.iter().min().unwrap();
        let max = *ints.iter().max().unwrap();
        Stream {
            name: format!("laplace s={scale}"),
            symbols: ints.iter().map(|&v| (v - min) as usize).collect(),
            alphabet: (max - min + 1) as usize,
            entropy: entropy(&ints),
            bits: None,
            ints: Some(ints),
        }
    }

    fn len(&self) -> usize {
        self.symbols.len()
    }

    fn vtz_encode(&self) -> Vec<u8> {
        match (&self.bits, &self.ints) {
            (Some(bits), _) => vtz_encode_bits(bits),
            (_, Some(ints)) => vtz_encode_ints(ints),
            _ => unreachable!(),
        }
    }

    fn vtz_decode(&self, bytes: &[u8]) -> Decoded {
        match self.bits {
            Some(_) => Decoded::Bits(vtz_decode_bits(bytes, self.len())),
            None => Decoded::Ints(vtz_decode_ints(bytes, self.len())),
        }
    }

    fn vtz_round_trips(&self, bytes: &[u8]) -> bool {
        match self.vtz_decode(bytes) {
            Decoded::Bits(b) => Some(b) == self.bits,
            Decoded::Ints(v) => Some(v) == self.ints,
        }
    }
}

enum Decoded {
    Bits(Vec<bool>),
    Ints(Vec<i64>),
}

fn streams() -> Vec<Stream> {
    vec![
        Stream::binary(0.05, 1_000_000, 1),
        Stream::binary(0.3, 1_000_000, 2),
        Stream::laplacian(3.0, 200_000, 3),
        Stream::laplacian(40.0, 200_000, 4),
    ]
}

// ---------------------------------------------------------------- the table

/// Best of `runs` wall times of `f`, in seconds.
fn best_time<T>(runs: usize, mut f: impl FnMut() -> T) -> f64 {
    (0..runs)
        .map(|_| {
            let t = Instant::now();
            black_box(f());
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn print_table(streams: &[Stream]) {
    println!();
    println!(
        "{:<16} {:<18} {:>9} {:>8} {:>8} {:>9} {:>11} {:>11}",
        "stream", "coder", "bytes", "bits/sym", "entropy", "over H %", "enc Msym/s", "dec Msym/s"
    );
    for s in streams {
        let n = s.len() as f64;
        let vtz = s.vtz_encode();
        assert!(s.vtz_round_trips(&vtz), "vtz round trip");
        let ac = ac_encode(&s.symbols, s.alphabet);
        assert_eq!(
            ac_decode(&ac, s.alphabet),
            s.symbols,
            "arithmetic-coding round trip"
        );
        let rows = [
            (
                "vtz range",
                vtz.len(),
                best_time(3, || s.vtz_encode()),
                best_time(3, || s.vtz_decode(&vtz)),
            ),
            (
                "arithmetic-coding",
                ac.len(),
                best_time(3, || ac_encode(&s.symbols, s.alphabet)),
                best_time(3, || ac_decode(&ac, s.alphabet)),
            ),
        ];
        for (coder, bytes, enc, dec) in rows {
            let bps = bytes as f64 * 8.0 / n;
            println!(
                "{:<16} {:<18} {:>9} {:>8.4} {:>8.4} {:>+9.2} {:>11.1} {:>11.1}",
                s.name,
                coder,
                bytes,
                bps,
                s.entropy,
                (bps / s.entropy - 1.0) * 100.0,
                n / enc / 1e6,
                n / dec / 1e6
            );
        }
    }
    println!();
}

// ---------------------------------------------------------------- criterion

fn bench_all(c: &mut Criterion) {
    for s in &streams() {
        let mut g = c.benchmark_group(&s.name);
        g.sample_size(10)
            .throughput(Throughput::Elements(s.len() as u64));
        let vtz = s.vtz_encode();
        let ac = ac_encode(&s.symbols, s.alphabet);
        g.bench_function("vtz/encode", |b| b.iter(|| s.vtz_encode()));
        g.bench_function("vtz/decode", |b| b.iter(|| s.vtz_decode(black_box(&vtz))));
        g.bench_function("arithmetic-coding/encode", |b| {
            b.iter(|| ac_encode(black_box(&s.symbols), s.alphabet))
        });
        g.bench_function("arithmetic-coding/decode", |b| {
            b.iter(|| ac_decode(black_box(&ac), s.alphabet))
        });
        g.finish();
    }
}

criterion_group! {
    name = benches;
    // No plots and fewer bootstrap resamples: both would take longer than the measurements.
    config = Criterion::default().without_plots().nresamples(10_000);
    targets = bench_all
}

fn main() {
    // The table only in a real benchmark run, not when `cargo test` smoke-runs the bench.
    if std::env::args().any(|a| a == "--bench") {
        print_table(&streams());
    }
    benches();
    Criterion::default().configure_from_args().final_summary();
}
