//! Scenes packed as uploads are: a `.glb` turned into a `.gltf` with its buffer beside it, and
//! `.zip` archives of chosen entries (files and symbolic links).
use serde_json::{json, Value};
use std::io::Write;

/// The scene of a `.glb` as a `.gltf` whose buffer is the file `scene.bin`.
pub fn as_gltf(glb: &[u8]) -> (Vec<u8>, Vec<u8>) {
    let word = |at: usize| u32::from_le_bytes(glb[at..at + 4].try_into().expect("4 bytes")) as usize;
    let json_len = word(12);
    let mut doc: Value = serde_json::from_slice(&glb[20..20 + json_len]).expect("GLB JSON chunk");
    let bin_at = 20 + json_len;
    let bin = glb[bin_at + 8..bin_at + 8 + word(bin_at)].to_vec();
    doc["buffers"][0]["uri"] = json!("scene.bin");
    (serde_json::to_vec(&doc).expect("JSON"), bin)
}

pub enum Entry<'a> {
    File(&'a str, &'a [u8]),
    Link(&'a str, &'a str),
}

pub fn zip_of(entries: &[Entry]) -> Vec<u8> {
    let mut w = zip::ZipWriter::new(std::io::Cursor::new(Vec::new()));
    let options = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    for e in entries {
        match e {
            Entry::File(name, bytes) => {
                w.start_file(*name, options).expect("entry");
                w.write_all(bytes).expect("write");
            }
            Entry::Link(name, target) => w.add_symlink(*name, *target, options).expect("link"),
        }
    }
    w.finish().expect("zip").into_inner()
}
