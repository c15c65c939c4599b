//! Integration tests of `tacmesh-serial`: the real Camsense capture from `testdata/` through
//! the pure decoder, and both backends through pseudo-terminal pairs (the Camsense capture
//! replayed at its baud rate, the RPLIDAR emulator in a square room).

mod capture;
mod pty;
mod util;
