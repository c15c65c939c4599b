//! Point-cloud and mesh files: PLY, PCD, XYZ and OBJ. (Being written.)
