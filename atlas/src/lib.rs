//! fresco-atlas: fills a packed UV atlas from the photos (paper 003, section 4.2).
//!
//! Will hold: per-view visibility, candidate views per chart, affine triangle transfer,
//! greedy least-to-best view fusion with gradient-weighted graph-cut seams (Boykov-Kolmogorov
//! max-flow), exposure leveling, filling unseen texels and padding.
