//! Edge-collapse simplification. (Being written.)
