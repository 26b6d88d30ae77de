//! 3D turtle L-systems whose tips are triangulated into a cover (the fractal-plant paper):
//! parsing and rewriting parametric rules, the turtle's heading/left/up frame, the tips of
//! the last stage, and (`cover`) their height-field or convex-hull triangulation.
//!
//! A word is a string of modules: a symbol and, for the drawing letters, an optional length
//! `(k a)` relative to the parameter `a` of the module it was rewritten from (`F(0.5a)`,
//! `F(1/3a)`, `B(2a)`; a bare `F` is `F(a)`). The axiom's `a` is [`LSystem::length`].
//!
//! | symbols | turtle |
//! | --- | --- |
//! | `F` and the letters `A B C D G S X` | move forward by the module's length, drawing |
//! | `f` | move forward without drawing |
//! | `+` `-` | turn about U by ±α (`R_U`) |
//! | `&` `^` | pitch about L by ±α (`R_L`) |
//! | `\` `/` | roll about H by ±α (`R_H`) |
//! | `*` `%`, `~` `?` | pitch, roll by ±β |
//! | `$` `@`, `!` `#` | pitch, roll by ±γ |
//! | `[` `]` | push, pop the turtle's state |
//!
//! Any other symbol is an [`Error::InvalidArgument`] naming it.

mod cover;

pub use cover::{Counts, Cover, counts, heightfield_mesh, hull_mesh};

use crate::error::{Error, Result};
use std::collections::BTreeMap;

/// The letters that draw like `F` (each may have its own rule).
pub const LETTERS: &str = "FABCDGSX";

/// At most this many modules in a derived word (about 100 MB of modules).
pub const MAX_MODULES: usize = 1 << 22;

/// An L-system as its rules file describes it (TOML, see [`LSystem::from_toml`]).
#[derive(Clone, Debug, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LSystem {
    /// The starting word.
    pub axiom: String,
    /// Rewriting steps.
    pub iterations: u32,
    /// Angle α of `+ - & ^ \ /`, in degrees.
    #[serde(default)]
    pub alpha: f64,
    /// Angle β of `* % ~ ?`, in degrees.
    #[serde(default)]
    pub beta: f64,
    /// Angle γ of `$ @ ! #`, in degrees.
    #[serde(default)]
    pub gamma: f64,
    /// The axiom's parameter `a` (the length of `F(a)`).
    #[serde(default = "one")]
    pub length: f64,
    /// How rotations compose: `"local"` (the turtle's own axes, the paper's equation 2,
    /// the default) or `"fixed"` (the axes of the turtle's starting frame).
    #[serde(default)]
    pub frame: Frame,
    /// One rule per letter: its replacement word (`F = "F[^F(0.5a)][&F(0.5a)]"`).
    #[serde(default)]
    pub rules: BTreeMap<String, String>,
}

fn one() -> f64 {
    1.0
}

/// How the turtle's rotations compose.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Frame {
    /// About the turtle's current H, L, U: `[H L U] ← [H L U] R` (the paper's equation 2).
    #[default]
    Local,
    /// About the fixed world axes: `[H L U] ← R [H L U]`, the paper's matrices applied to
    /// x, y, z (`R_U` turns about z, `R_L` about y, `R_H` about x; the turtle starts heading
    /// up, along z). This reproduces the paper's Table I.
    Fixed,
}

/// One module of a word: a symbol and, for a letter, its length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Module {
    /// The symbol.
    pub symbol: char,
    /// A letter's length (a multiple of its rule's `a`); 0 for the other symbols.
    pub length: f64,
}

/// What the turtle drew from the derived word.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Plant {
    /// The modules of the derived word.
    pub modules: usize,
    /// Every drawn segment: start, end, and its bracket depth.
    pub segments: Vec<([f64; 3], [f64; 3], usize)>,
    /// The tips of the last stage: the ends of the segments drawn at the deepest bracket
    /// depth, distinct, in drawing order (the vertices the paper triangulates).
    pub tips: Vec<[f64; 3]>,
}

impl LSystem {
    /// Read a rules file: `axiom`, `iterations`, `alpha`, `beta`, `gamma` (degrees),
    /// `length`, `frame` and a `[rules]` table of one letter each. Checks every word.
    pub fn from_toml(text: &str) -> Result<LSystem> {
        let ls: LSystem =
            toml::from_str(text).map_err(|e| Error::invalid(format!("rules file: {e}")))?;
        ls.check()?;
        Ok(ls)
    }

    /// Check the angles, the length, the rules' keys and every word's symbols.
    pub fn check(&self) -> Result<()> {
        for (name, v) in [
            ("alpha", self.alpha),
            ("beta", self.beta),
            ("gamma", self.gamma),
        ] {
            if !v.is_finite() {
                return Err(Error::invalid(format!(
                    "{name} = {v} is not a finite angle"
                )));
            }
        }
        if !(self.length.is_finite() && self.length > 0.0) {
            return Err(Error::invalid(format!(
                "length = {} is not a positive length",
                self.length
            )));
        }
        parse_word(&self.axiom).map_err(|e| e.context("axiom"))?;
        for (k, body) in &self.rules {
            rule_letter(k)?;
            parse_word(body).map_err(|e| e.context(format!("rule {k}")))?;
        }
        Ok(())
    }

    /// The word after [`LSystem::iterations`] parallel rewrites; [`Error::LimitExceeded`]
    /// past [`MAX_MODULES`].
    pub fn derive(&self) -> Result<Vec<Module>> {
        self.check()?;
        let mut rules: BTreeMap<char, Vec<Module>> = BTreeMap::new();
        for (k, body) in &self.rules {
            rules.insert(rule_letter(k)?, parse_word(body)?);
        }
        let mut word: Vec<Module> = parse_word(&self.axiom)?
            .into_iter()
            .map(|m| Module {
                length: m.length * self.length,
                ..m
            })
            .collect();
        for step in 0..self.iterations {
            let next_len: usize = word
                .iter()
                .map(|m| rules.get(&m.symbol).map_or(1, Vec::len))
                .fold(0usize, usize::saturating_add);
            if next_len > MAX_MODULES {
                return Err(Error::limit(format!(
                    "step {} of the L-system would make {next_len} modules (at most {MAX_MODULES})",
                    step + 1
                )));
            }
            let mut next = Vec::with_capacity(next_len);
            for m in &word {
                match rules.get(&m.symbol) {
                    Some(body) => next.extend(body.iter().map(|r| Module {
                        symbol: r.symbol,
                        length: r.length * m.length,
                    })),
                    None => next.push(*m),
                }
            }
            word = next;
        }
        Ok(word)
    }

    /// Derive the word and run the turtle over it: the segments and the tips.
    pub fn grow(&self) -> Result<Plant> {
        let word = self.derive()?;
        Ok(interpret(
            &word,
            [self.alpha, self.beta, self.gamma].map(f64::to_radians),
            self.frame,
        ))
    }
}

/// A rule's key: one drawing letter.
fn rule_letter(k: &str) -> Result<char> {
    let mut cs = k.chars();
    match (cs.next(), cs.next()) {
        (Some(c), None) if LETTERS.contains(c) => Ok(c),
        _ => Err(Error::invalid(format!(
            "rule key {k:?}: a rule rewrites one of the letters {LETTERS}"
        ))),
    }
}

/// Parse a word: symbols, letters with optional `(k a)` lengths, whitespace ignored.
pub fn parse_word(text: &str) -> Result<Vec<Module>> {
    let mut out = Vec::new();
    let mut it = text.chars().peekable();
    while let Some(c) = it.next() {
        if c.is_whitespace() {
            continue;
        }
        let symbol = if c == '\u{2212}' { '-' } else { c };
        if LETTERS.contains(symbol) {
            let mut length = 1.0;
            if it.peek() == Some(&'(') {
                it.next();
                let mut inner = String::new();
                loop {
                    match it.next() {
                        Some(')') => break,
                        Some(ch) => inner.push(ch),
                        None => {
                            return Err(Error::invalid(format!(
                                "{symbol}({inner}: no closing parenthesis"
                            )));
                        }
                    }
                }
                length = parse_length(&inner).ok_or_else(|| {
                    Error::invalid(format!(
                        "{symbol}({inner}): a length is a multiple of a (a, 0.5a, 1/3a, 2*a, a/4)"
                    ))
                })?;
            }
            out.push(Module { symbol, length });
        } else if "f+-&^\\/*%~?$@!#[]".contains(symbol) {
            out.push(Module {
                symbol,
                length: if symbol == 'f' { 1.0 } else { 0.0 },
            });
        } else {
            return Err(Error::invalid(format!(
                "unknown symbol {symbol:?} in {text:?} (letters {LETTERS}, f, + - & ^ \\ / * % ~ ? $ @ ! # [ ])"
            )));
        }
    }
    let mut depth = 0usize;
    for m in &out {
        match m.symbol {
            '[' => depth += 1,
            ']' if depth == 0 => {
                return Err(Error::invalid(format!("{text:?}: ] without a [")));
            }
            ']' => depth -= 1,
            _ => {}
        }
    }
    Ok(out)
}

/// `a`, `0.5a`, `1/3a`, `2*a`, `a/4` → the factor of `a`.
fn parse_length(s: &str) -> Option<f64> {
    let s: String = s.chars().filter(|c| !c.is_whitespace()).collect();
    let number = |t: &str| -> Option<f64> {
        if t.is_empty() {
            return Some(1.0);
        }
        match t.split_once('/') {
            Some((p, q)) => Some(p.parse::<f64>().ok()? / q.parse::<f64>().ok()?),
            None => t.parse::<f64>().ok(),
        }
    };
    let k = if let Some(rest) = s.strip_prefix("a/") {
        1.0 / rest.parse::<f64>().ok()?
    } else {
        let coef = s.strip_suffix('a')?;
        number(coef.strip_suffix('*').unwrap_or(coef))?
    };
    (k.is_finite() && k > 0.0).then_some(k)
}

type Mat = [[f64; 3]; 3];

fn mul(a: &Mat, b: &Mat) -> Mat {
    let mut r = [[0.0; 3]; 3];
    for (i, row) in r.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = (0..3).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    r
}

/// The paper's equation 3: rotations about U, L and H (axis 0, 1, 2) by `t` radians.
fn rotation(axis: usize, t: f64) -> Mat {
    let (s, c) = t.sin_cos();
    match axis {
        0 => [[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]],
        1 => [[c, 0.0, -s], [0.0, 1.0, 0.0], [s, 0.0, c]],
        _ => [[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]],
    }
}

/// Run the turtle: it starts at the origin heading up (H = +z, L = +x, U = +y, H × L = U).
fn interpret(word: &[Module], angles: [f64; 3], frame: Frame) -> Plant {
    // Columns H, L, U.
    let mut m: Mat = [[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]];
    let mut pos = [0.0f64; 3];
    let mut stack = Vec::new();
    let mut plant = Plant {
        modules: word.len(),
        ..Plant::default()
    };
    for md in word {
        let turn = match md.symbol {
            '+' => Some((0, angles[0])),
            '-' => Some((0, -angles[0])),
            '&' => Some((1, angles[0])),
            '^' => Some((1, -angles[0])),
            '\\' => Some((2, angles[0])),
            '/' => Some((2, -angles[0])),
            '*' => Some((1, angles[1])),
            '%' => Some((1, -angles[1])),
            '~' => Some((2, angles[1])),
            '?' => Some((2, -angles[1])),
            '$' => Some((1, angles[2])),
            '@' => Some((1, -angles[2])),
            '!' => Some((2, angles[2])),
            '#' => Some((2, -angles[2])),
            _ => None,
        };
        if let Some((axis, t)) = turn {
            let r = rotation(axis, t);
            m = match frame {
                Frame::Local => mul(&m, &r),
                Frame::Fixed => mul(&r, &m),
            };
            continue;
        }
        match md.symbol {
            '[' => stack.push((pos, m)),
            ']' => (pos, m) = stack.pop().expect("brackets balanced by parse_word"),
            s => {
                let end = [0, 1, 2].map(|i| pos[i] + md.length * m[i][0]);
                if s != 'f' {
                    plant.segments.push((pos, end, stack.len()));
                }
                pos = end;
            }
        }
    }
    let deepest = plant.segments.iter().map(|s| s.2).max().unwrap_or(0);
    let mut seen = std::collections::HashSet::new();
    for s in &plant.segments {
        if s.2 == deepest && seen.insert(key(s.1)) {
            plant.tips.push(s.1);
        }
    }
    plant
}

/// A point's identity up to rounding noise (1e-9).
pub(crate) fn key(p: [f64; 3]) -> [i64; 3] {
    p.map(|v| (v * 1e9).round() as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lengths_parse() {
        for (s, k) in [("a", 1.0), ("0.5a", 0.5), ("1/3a", 1.0 / 3.0), ("2*a", 2.0)] {
            assert_eq!(parse_length(s), Some(k), "{s}");
        }
        assert_eq!(parse_length("a/4"), Some(0.25));
        assert_eq!(parse_length("b"), None);
        assert_eq!(parse_length("-1a"), None);
    }

    #[test]
    fn unknown_symbol_is_named() {
        let e = parse_word("F[+Q]").unwrap_err();
        assert!(matches!(e, Error::InvalidArgument { .. }));
        assert!(e.to_string().contains("'Q'"), "{e}");
        assert!(parse_word("F]").is_err());
    }

    #[test]
    fn rewriting_scales_lengths() {
        let ls = LSystem {
            axiom: "F(2a)".into(),
            iterations: 2,
            alpha: 30.0,
            beta: 0.0,
            gamma: 0.0,
            length: 1.0,
            frame: Frame::Local,
            rules: [("F".to_string(), "F[^F(0.5a)]".to_string())].into(),
        };
        let w = ls.derive().unwrap();
        // F[^F(.5)] → F[^F(.5)][^F(.5)[^F(.25)]]
        assert_eq!(w.len(), 13);
        let lens: Vec<f64> = w
            .iter()
            .filter(|m| m.symbol == 'F')
            .map(|m| m.length)
            .collect();
        assert_eq!(lens, vec![2.0, 1.0, 1.0, 0.5]);
    }

    #[test]
    fn turtle_turns_like_the_matrices() {
        // Up 1, then pitch by 90°: heading becomes ±x or ±y, still unit.
        let w = parse_word("F&F+F").unwrap();
        let p = interpret(&w, [90f64.to_radians(), 0.0, 0.0], Frame::Local);
        assert_eq!(p.segments.len(), 3);
        let e = p.segments[2].1;
        let d = ((e[0] - 1.0).powi(2) + (e[1] - 1.0).powi(2) + (e[2] - 1.0).powi(2)).sqrt();
        let len = |s: &([f64; 3], [f64; 3], usize)| {
            (0..3)
                .map(|i| (s.1[i] - s.0[i]).powi(2))
                .sum::<f64>()
                .sqrt()
        };
        assert!(p.segments.iter().all(|s| (len(s) - 1.0).abs() < 1e-12));
        // Three orthogonal unit moves end at distance √3 from the origin.
        let r = (e[0].powi(2) + e[1].powi(2) + e[2].powi(2)).sqrt();
        assert!((r - 3f64.sqrt()).abs() < 1e-12, "{e:?} {d}");
    }
}
