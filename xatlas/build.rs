//! Builds xatlas (vendor/, from the crates.io package xatlas-rs 0.1.3, MIT) and our C shim
//! with the system C++ compiler. Single-threaded (`XA_MULTITHREADED=0`): the same input
//! gives the same atlas, and xatlas starts no threads of its own.
fn main() {
    println!("cargo:rerun-if-changed=vendor/xatlas.cpp");
    println!("cargo:rerun-if-changed=vendor/xatlas.h");
    println!("cargo:rerun-if-changed=src/shim.cpp");
    cc::Build::new()
        .cpp(true)
        .std("c++11")
        .file("vendor/xatlas.cpp")
        .file("src/shim.cpp")
        .define("XA_MULTITHREADED", "0")
        .define("NDEBUG", None)
        .opt_level(2)
        .debug(false)
        .warnings(false)
        .compile("guidebake_xatlas");
}
