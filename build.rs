//! Generates Rust bindings for the Embree 4 headers and links `libembree4`; with the `denoise`
//! feature, checks that Open Image Denoise is unpacked and sets the rpath to it.
//!
//! Embree 4 is looked for in this order: `$EMBREE_DIR` (a folder with `include/embree4` and
//! `lib/libembree4.so`), the system (`/usr/include/embree4`, as Debian trixie's `libembree-dev`
//! installs it), then `.deps/embree`, which `scripts/embree.sh` fills on bookworm (Intel's
//! library from the `embreex` wheel, Debian's headers). A library outside the system's search
//! path is found again at run time through an rpath to its folder, and `$ORIGIN/../lib/relume`.
//! Calls that bindgen cannot emit (the inline argument initialisers) live in
//! `src/embree/version.rs`.
use std::env;
use std::path::{Path, PathBuf};

const SYSTEM_INCLUDE: &str = "/usr/include";

/// Where the headers are, and the folder of a library the system's loader does not know.
struct Embree {
    include: PathBuf,
    lib: Option<PathBuf>,
}

fn main() {
    println!("cargo:rerun-if-changed=build.rs");
    if env::var_os("CARGO_FEATURE_DENOISE").is_some() {
        link_oidn();
    }
    let embree = find_embree();
    let header = embree.include.join("embree4/rtcore.h");
    println!("cargo:rerun-if-changed={}", header.display());
    if let Some(lib) = &embree.lib {
        println!("cargo:rustc-link-search=native={}", lib.display());
        println!("cargo:rustc-link-arg=-Wl,-rpath,{}", lib.display());
    }
    println!("cargo:rustc-link-lib=embree4");
    generate_bindings(&embree.include, &header);
}

/// `$EMBREE_DIR`, the system, then `.deps/embree`; a build error that says how to get one.
fn find_embree() -> Embree {
    println!("cargo:rerun-if-env-changed=EMBREE_DIR");
    let has_header = |include: &Path| include.join("embree4/rtcore.h").exists();
    if let Ok(dir) = env::var("EMBREE_DIR") {
        let dir = PathBuf::from(dir);
        let (include, lib) = (dir.join("include"), dir.join("lib"));
        if !has_header(&include) || !lib.join("libembree4.so").exists() {
            fail(&format!("EMBREE_DIR={} holds no include/embree4/rtcore.h and lib/libembree4.so", dir.display()));
        }
        return Embree { include, lib: Some(lib.canonicalize().unwrap_or(lib)) };
    }
    if has_header(Path::new(SYSTEM_INCLUDE)) {
        return Embree { include: PathBuf::from(SYSTEM_INCLUDE), lib: None };
    }
    let deps =
        PathBuf::from(env::var("CARGO_MANIFEST_DIR").expect("cargo sets CARGO_MANIFEST_DIR")).join(".deps/embree");
    println!("cargo:rerun-if-changed={}", deps.join("lib/libembree4.so").display());
    if has_header(&deps.join("include")) && deps.join("lib/libembree4.so").exists() {
        let lib = deps.join("lib");
        return Embree { include: deps.join("include"), lib: Some(lib.canonicalize().unwrap_or(lib)) };
    }
    fail(
        "Embree 4 not found (no $EMBREE_DIR, no /usr/include/embree4, no .deps/embree).\n\
         On Debian bookworm run scripts/setup.sh (scripts/embree.sh unpacks Intel's Embree 4.4 into \
         .deps/embree); on trixie or later `apt-get install libembree-dev`; or set EMBREE_DIR to a \
         folder holding include/embree4/ and lib/libembree4.so.",
    )
}

fn generate_bindings(include: &Path, header: &Path) {
    let bindings = bindgen::Builder::default()
        .header(header.to_string_lossy())
        .clang_arg(format!("-I{}", include.display()))
        .allowlist_function("rtc.*")
        .allowlist_type("RTC.*")
        .allowlist_var("RTC.*")
        .default_enum_style(bindgen::EnumVariation::Consts)
        .prepend_enum_name(false)
        .derive_default(true)
        .layout_tests(false)
        .generate()
        .unwrap_or_else(|e| fail(&format!("bindgen failed on {}: {e}. Is libclang-dev installed?", header.display())));
    let out = PathBuf::from(env::var("OUT_DIR").expect("cargo sets OUT_DIR")).join("embree_bindings.rs");
    bindings.write_to_file(&out).unwrap_or_else(|e| fail(&format!("cannot write {}: {e}", out.display())));
}

fn fail(message: &str) -> ! {
    eprintln!("error: {message}");
    std::process::exit(1);
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
