//! The checked-in header `include/guidebake.h` is what cbindgen generates from the sources
//! now: the test fails when an exported function or type changed without regenerating it.
//! `GUIDEBAKE_BLESS=1 cargo test -p guidebake-kernels-capi --test header` rewrites it.

use std::path::Path;

#[test]
fn header_is_up_to_date() {
    let crate_dir = Path::new(env!("CARGO_MANIFEST_DIR"));
    let config =
        cbindgen::Config::from_file(crate_dir.join("cbindgen.toml")).expect("cbindgen.toml parses");
    let bindings = cbindgen::Builder::new()
        .with_config(config)
        .with_src(crate_dir.join("src/lib.rs"))
        .generate()
        .expect("cbindgen generates the header");
    let mut generated = Vec::new();
    bindings.write(&mut generated);
    let generated = String::from_utf8(generated).expect("UTF-8 header");
    let path = crate_dir.join("include/guidebake.h");
    if std::env::var_os("GUIDEBAKE_BLESS").is_some() {
        std::fs::write(&path, &generated).expect("header written");
        return;
    }
    let checked_in = std::fs::read_to_string(&path).unwrap_or_default();
    if checked_in != generated {
        let line = checked_in
            .lines()
            .zip(generated.lines())
            .position(|(a, b)| a != b)
            .map_or(
                checked_in.lines().count().min(generated.lines().count()) + 1,
                |l| l + 1,
            );
        panic!(
            "capi/include/guidebake.h is stale (first difference at line {line}); regenerate \
             it with GUIDEBAKE_BLESS=1 cargo test -p guidebake-kernels-capi --test header"
        );
    }
}
