//! Marching cubes over a sparse signed distance. (Being written.)
