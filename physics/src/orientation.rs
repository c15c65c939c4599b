//! Which way a mesh faces.
