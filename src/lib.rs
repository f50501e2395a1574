//! guidebake-suite: the root package that owns the workspace's integration tests (`tests/`)
//! and criterion benches (`benches/`). It has no code of its own.
