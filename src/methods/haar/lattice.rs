//! The Haar section's value lattice: a lattice code becomes an output sample through the
//! shared lattice and output rounding of `quant`.

use crate::model::{SampleType, ValueMapping};
use crate::quant::{finish, height_of};

/// How a lattice code becomes an output sample (identical in encoder and decoder).
#[derive(Clone, Copy, Debug)]
pub(super) struct Lattice {
    pub(super) step: f64,
    pub(super) offset: f64,
    pub(super) out: Output,
}

/// The output sample type and value mapping a value is rounded to.
#[derive(Clone, Copy, Debug)]
pub(super) struct Output {
    st: SampleType,
    mapping: ValueMapping,
}

impl Output {
    pub(super) fn new(st: SampleType, mapping: ValueMapping) -> Output {
        Output { st, mapping }
    }
}

impl Lattice {
    #[inline]
    pub(super) fn value(&self, code: i64) -> Option<f64> {
        let v = height_of(code, self.step, self.offset);
        if !v.is_finite() {
            return None;
        }
        let v = finish(v, self.out.st, self.out.mapping);
        v.is_finite().then_some(v)
    }
}
