//! Ground truth for tacmesh. (Being written.)
