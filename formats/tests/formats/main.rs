//! Integration tests of `tacmesh-formats`: real sample files from `testdata/`, round trips
//! through files, rejection of broken files, and a seeded mangling run that must never panic.

mod util;

mod mangle;
mod non_finite;
mod real_data;
mod rejection;
mod round_trip;
