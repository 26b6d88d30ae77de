//! The value lattice: how an integer lattice code becomes an output sample.

use crate::model::{SampleType, ValueMapping};

/// How a lattice code becomes an output sample (identical in encoder and decoder).
#[derive(Clone, Copy, Debug)]
pub(super) struct Lattice {
    pub(super) step: f64,
    pub(super) offset: f64,
    pub(super) out: Output,
}

#[derive(Clone, Copy, Debug)]
pub(super) enum Output {
    F64,
    F32,
    /// Rounded to the nearest source code, clamped to the type's range.
    Int {
        mapping: ValueMapping,
        lo: f64,
        hi: f64,
    },
}

impl Output {
    pub(super) fn new(st: SampleType, mapping: ValueMapping) -> Output {
        match st.int_range() {
            Some((lo, hi)) => Output::Int { mapping, lo, hi },
            None if st == SampleType::F32 => Output::F32,
            None => Output::F64,
        }
    }
}

impl Lattice {
    #[inline]
    pub(super) fn value(&self, code: i64) -> Option<f64> {
        let v = self.offset + self.step * code as f64;
        if !v.is_finite() {
            return None;
        }
        let v = match self.out {
            Output::F64 => v,
            Output::F32 => v as f32 as f64,
            Output::Int { mapping, lo, hi } => {
                let c = ((v - mapping.offset) / mapping.scale).round().clamp(lo, hi);
                mapping.offset + mapping.scale * c
            }
        };
        v.is_finite().then_some(v)
    }
}
