//! Compiles only if `guidebake-kernels` builds without std and without alloc.
#![no_std]

pub use guidebake_kernels;
