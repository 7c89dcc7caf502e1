//! Generate the reference tug's message structs from its DBC (the same generator users get
//! from `bywire dbc gen-rust`).

use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dbc = "dbc/reference-tug.dbc";
    println!("cargo::rerun-if-changed={dbc}");
    let text = std::fs::read_to_string(dbc)?;
    let (db, _) = bywire_dbc::parse_str(&text, bywire_dbc::Mode::Strict)
        .map_err(|e| format!("{dbc}: {e}"))?;
    let out = PathBuf::from(std::env::var("OUT_DIR")?).join("reference_tug.rs");
    std::fs::write(out, bywire_dbc::codegen::generate(&db))?;
    Ok(())
}
