//! Least-squares stencil weights, fitted by the encoder only (floating point is fine here:
//! the decoder never fits, it applies the stored integer weights).

#![allow(clippy::needless_range_loop)] // index loops read best in matrix code

/// Weights are stored as i16 in units of 2^-SHIFT.
pub const SHIFT: u32 = 10;
/// Fewer samples than this give no fit (all-zero weights).
const MIN_SAMPLES: usize = 64;

/// The normal equations of one fit.
pub struct Normal<const N: usize> {
    a: [[f64; N]; N],
    b: [f64; N],
    n: usize,
}

impl<const N: usize> Normal<N> {
    pub fn new() -> Self {
        Normal {
            a: [[0.0; N]; N],
            b: [0.0; N],
            n: 0,
        }
    }

    /// Add one sample: features `f`, target `t`.
    #[inline]
    pub fn add(&mut self, f: &[i64; N], t: f64) {
        for p in 0..N {
            let fp = f[p] as f64;
            self.b[p] += fp * t;
            for q in p..N {
                self.a[p][q] += fp * f[q] as f64;
            }
        }
        self.n += 1;
    }

    /// Ridge-regularised solution, rounded to the stored weights.
    pub fn solve(&self) -> [i16; N] {
        if self.n < MIN_SAMPLES {
            return [0; N];
        }
        let mut m = self.a;
        for p in 0..N {
            for q in 0..p {
                m[p][q] = m[q][p];
            }
        }
        let tr: f64 = (0..N).map(|p| m[p][p]).sum::<f64>() / N as f64;
        let mut v = self.b;
        for (p, row) in m.iter_mut().enumerate() {
            row[p] += 1e-3 * tr + 1e-9;
        }
        // Gaussian elimination with partial pivoting.
        for col in 0..N {
            let piv = (col..N)
                .max_by(|&i, &j| m[i][col].abs().total_cmp(&m[j][col].abs()))
                .unwrap_or(col);
            m.swap(col, piv);
            v.swap(col, piv);
            if m[col][col] == 0.0 {
                return [0; N];
            }
            for r in col + 1..N {
                let f = m[r][col] / m[col][col];
                for c in col..N {
                    m[r][c] -= f * m[col][c];
                }
                v[r] -= f * v[col];
            }
        }
        let mut c = [0f64; N];
        for r in (0..N).rev() {
            let mut acc = v[r];
            for k in r + 1..N {
                acc -= m[r][k] * c[k];
            }
            c[r] = acc / m[r][r];
        }
        c.map(|x| {
            let q = (x * (1u32 << SHIFT) as f64).round();
            if q.is_finite() {
                q.clamp(-32768.0, 32767.0) as i16
            } else {
                0
            }
        })
    }
}
