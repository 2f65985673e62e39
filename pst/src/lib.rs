//! fresco-pst: point-sampled textures for meshes too large for memory (paper 000, Boubekeur and Schlick).
//!
//! Will hold: out-of-core two-pass m-grid sampling, the k-NN Hermite-kernel colour field,
//! local up-sampling from per-cell files, LRU down-sampling, editing operations and streaming
//! application of the texture back onto the full mesh.
