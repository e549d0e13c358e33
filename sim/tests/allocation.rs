//! A height file's header never makes the process allocate what it only
//! claims: memory follows the bytes the file holds.

use std::path::Path;

use arcnav_sim::heightmap::HeightGrid;
use arcnav_testkit::alloc::Largest;

#[global_allocator]
static ALLOC: Largest = Largest::new();

#[test]
fn height_file_headers_claiming_billions_of_samples_cost_only_their_bytes() {
    let asc =
        b"ncols 4\nnrows 4333333333333\nxllcorner 0\nyllcorner 0\ncellsize 1\n1 2 3 4\n".to_vec();
    let hdr = "{'descr': '<f4', 'fortran_order': False, 'shape': (100000, 100000), }";
    let mut npy = b"\x93NUMPY\x01\x00".to_vec();
    npy.extend_from_slice(&(hdr.len() as u16).to_le_bytes());
    npy.extend_from_slice(hdr.as_bytes());
    npy.extend_from_slice(&[0u8; 64]);
    for (name, bytes) in [("h.asc", asc), ("h.npy", npy)] {
        ALLOC.reset();
        let err = HeightGrid::parse(Path::new(name), bytes, Some(1.0), None).unwrap_err();
        assert!(
            ALLOC.largest() < 1 << 20,
            "{name}: allocated {} bytes ({err})",
            ALLOC.largest()
        );
    }
}
