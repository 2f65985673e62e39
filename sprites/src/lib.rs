//! fresco-sprites: texture sprites splatted on surfaces (paper 001, Lefebvre, Hornus and Neyret).
//!
//! Will hold: the N^3-tree with a packed indirection pool, the sprite table and leaf vectors,
//! insertion with splitting, blending modes, filtering, octree textures and baking into a UV atlas.
