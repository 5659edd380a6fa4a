//! Fuzzes the msh reader: `parse_mesh` must return Ok or Err, never panic,
//! and never allocate beyond what the input size justifies.
#![no_main]

use libfuzzer_sys::fuzz_target;
use sim_server::mesh::io::{MeshFormat, parse_mesh};

fuzz_target!(|data: &[u8]| {
    let _ = parse_mesh("fuzz.msh", data, MeshFormat::Msh);
});
