//! fresco-atlas: fills a packed UV atlas from the photos (paper 003, section 4.2).
pub mod graph_cut;
pub mod max_flow;
