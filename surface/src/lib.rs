//! fresco-surface: cameras and sparse points to a watertight mesh (paper 003, section 3).
//!
//! Will hold: dense depth maps and their fusion into an oriented point cloud, silhouettes and
//! the visual hull, screened Poisson reconstruction (Kazhdan and Hoppe 2013) on an adaptive
//! octree, iso-surface extraction, density trimming, mesh clean-up and quadric decimation.
