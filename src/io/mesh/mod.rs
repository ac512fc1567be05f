//! Mesh writers (in progress).
