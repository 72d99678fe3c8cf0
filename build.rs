//! Generates Rust bindings for the system Embree 3 headers and links `libembree3`; with the
//! `denoise` feature, checks that Open Image Denoise is unpacked and sets the rpath to it.
//!
//! Debian bookworm ships Embree 3.13.5 as `libembree-dev` (`/usr/include/embree3/rtcore.h`).
//! Version-specific calls that bindgen cannot emit (inline helpers, Embree 4's changed query
//! signatures) live in `src/embree/version.rs`, so a port to Embree 4 touches that file alone.
use std::env;
use std::path::{Path, PathBuf};

const HEADER: &str = "/usr/include/embree3/rtcore.h";

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if env::var_os("CARGO_FEATURE_DENOISE").is_some() {
        link_oidn();
    }
    println!("cargo:rerun-if-env-changed=EMBREE_INCLUDE_DIR");
    let header = match env::var("EMBREE_INCLUDE_DIR") {
        Ok(dir) => Path::new(&dir).join("embree3/rtcore.h"),
        Err(_) => PathBuf::from(HEADER),
    };
    if !header.exists() {
        eprintln!(
            "error: Embree 3 headers not found at {}.\n\
             Install them with `apt-get install libembree-dev libclang-dev clang` \
             (or run scripts/setup.sh), or set EMBREE_INCLUDE_DIR to the folder holding embree3/.",
            header.display()
        );
        std::process::exit(1);
    }
    println!("cargo:rerun-if-changed={}", header.display());
    println!("cargo:rustc-link-lib=embree3");

    let bindings = bindgen::Builder::default()
        .header(header.to_string_lossy())
        .allowlist_function("rtc.*")
        .allowlist_type("RTC.*")
        .allowlist_var("RTC.*")
        .default_enum_style(bindgen::EnumVariation::Consts)
        .prepend_enum_name(false)
        .derive_default(true)
        .layout_tests(false)
        .generate()
        .unwrap_or_else(|e| {
            eprintln!("error: bindgen failed on {}: {e}. Is libclang-dev installed?", header.display());
            std::process::exit(1);
        });
    let out = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("embree_bindings.rs");
    bindings.write_to_file(&out).unwrap_or_else(|e| {
        eprintln!("error: cannot write {}: {e}", out.display());
        std::process::exit(1);
    });
}

/// The oidn crate links `libOpenImageDenoise` from `$OIDN_DIR/lib` (scripts/oidn.sh unpacks it
/// there). The binary finds it again at run time through an rpath to that folder, from any
/// working directory, and through `$ORIGIN/../lib/relume` where the Dockerfile installs it.
fn link_oidn() {
    println!("cargo:rerun-if-env-changed=OIDN_DIR");
    let dir = env::var("OIDN_DIR").unwrap_or_default();
    let lib = Path::new(&dir).join("lib");
    if dir.is_empty() || !lib.join("libOpenImageDenoise.so").exists() {
        eprintln!(
            "error: Open Image Denoise not found in {}.\n\
             Run scripts/setup.sh (it unpacks Intel's OIDN 2.5.1 into .deps/oidn), set OIDN_DIR to \
             a folder holding lib/libOpenImageDenoise.so, or build without it: \
             cargo build --no-default-features",
            lib.display()
        );
        std::process::exit(1);
    }
    let lib = lib.canonicalize().unwrap_or(lib);
    println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib.display());
    println!("cargo:rustc-link-arg=-Wl,-rpath,$ORIGIN/../lib/relume");
}
