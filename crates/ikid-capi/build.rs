//! Gives libikid.so its SONAME, `libikid.so.<major>`, so a host records the ABI it was linked
//! against (not the unversioned development link `libikid.so`) and an ABI break (a new major)
//! cannot be loaded in its place. `make capi`/`make install` add the versioned file names.

fn main() {
    let target_os = std::env::var("CARGO_CFG_TARGET_OS").unwrap_or_default();
    if target_os == "linux" || target_os == "freebsd" || target_os == "android" {
        let major = env!("CARGO_PKG_VERSION_MAJOR");
        println!("cargo:rustc-cdylib-link-arg=-Wl,-soname,libikid.so.{major}");
    }
    println!("cargo:rerun-if-changed=build.rs");
}
