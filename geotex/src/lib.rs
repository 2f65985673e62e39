//! fresco-geotex: resizing models that carry geometric texture (paper 002).
//!
//! Will hold: curvature features, mean-shift segmentation, implicit fairing, displacement
//! extraction, non-homogeneous resizing of the base, re-synthesis of the texture at its original scale.
