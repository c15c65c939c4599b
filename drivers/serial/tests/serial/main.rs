//! Integration tests of `tacmesh-serial`: the real Camsense capture from `shared/data` through
//! the pure decoder, and both backends through pseudo-terminal pairs (the Camsense capture
//! replayed at its baud rate, the RPLIDAR emulator in a square room).

mod capture;
mod pty;
mod util;
