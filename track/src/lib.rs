//! Object identity across frames and per-object incremental fusion (work in progress).
