//! guidebake-suite: the root package that owns the workspace's integration tests (`tests/`)
//! and criterion benches (`benches/`), the bodies of the fuzz targets ([`fuzzing`]), so
//! that `cargo fuzz` (in `fuzz/`) and `cargo test` (which replays the checked-in corpus)
//! run the same code, and the traversal workloads the tests and the benches share
//! ([`traverse_scenes`]).

pub mod fuzzing;
pub mod traverse_scenes;
