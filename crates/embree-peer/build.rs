//! Compile the C++ peer against Embree 3 when its headers are installed (Debian:
//! libembree-dev); otherwise build without it, and the binary says what to install.

use std::path::Path;

fn main() {
    println!("cargo::rustc-check-cfg=cfg(embree)");
    println!("cargo::rerun-if-changed=cpp/peer.cpp");
    println!("cargo::rerun-if-changed=/usr/include/embree3/rtcore.h");
    if !Path::new("/usr/include/embree3/rtcore.h").exists() {
        return;
    }
    cc::Build::new().cpp(true).file("cpp/peer.cpp").flag("-std=c++17").opt_level(3).compile("splat_embree_peer");
    println!("cargo::rustc-link-lib=embree3");
    println!("cargo::rustc-cfg=embree");
}
