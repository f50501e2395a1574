//! Builds xatlas (vendor/, from the crates.io package xatlas-rs 0.1.3, MIT) and our C shim
//! with the system C++ compiler. Single-threaded (`XA_MULTITHREADED=0`): the same input
//! gives the same atlas, and xatlas starts no threads of its own (atlases may be used on
//! several threads at once, one thread per atlas).
fn main() {
    println!("cargo:rerun-if-changed=vendor/xatlas.cpp");
    println!("cargo:rerun-if-changed=vendor/xatlas.h");
    println!("cargo:rerun-if-changed=src/shim.cpp");
    println!("cargo:rerun-if-changed=src/charts.cpp");
    let mut build = cc::Build::new();
    // Under AddressSanitizer (cargo-fuzz's default, `-Zsanitizer=address` in the rustflags)
    // the C++ is instrumented too, so a bad access inside xatlas is reported, not only bad
    // frees. Rust's ASan runtime serves the instrumented objects (GCC's and Clang's
    // instrumentation call the same runtime ABI).
    println!("cargo:rerun-if-env-changed=CARGO_ENCODED_RUSTFLAGS");
    let rustflags = std::env::var("CARGO_ENCODED_RUSTFLAGS").unwrap_or_default();
    let asan = rustflags
        .split('\x1f')
        .any(|f| f.ends_with("sanitizer=address"))
        || rustflags.contains("-Zsanitizer=address");
    if asan {
        build
            .flag("-fsanitize=address")
            .flag("-fno-omit-frame-pointer");
    }
    build
        .cpp(true)
        .std("c++11")
        // charts.cpp includes vendor/xatlas.cpp (it reads xatlas's internal charts).
        .file("src/charts.cpp")
        .file("src/shim.cpp")
        .define("XA_MULTITHREADED", "0")
        .define("NDEBUG", None)
        .opt_level(2)
        .debug(false)
        .warnings(false)
        .compile("guidebake_xatlas");
}
