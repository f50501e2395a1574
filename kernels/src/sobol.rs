//! `sobol`: to be written (see the module table in the crate docs).
