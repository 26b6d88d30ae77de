//! What an encoder predicts before it codes: the median edge detector with activity
//! contexts (grid, FIS subgrids, Haar's LL band).

pub(crate) mod med;
