//! fresco-param: a low-distortion parameterisation for surfaces of any genus (paper 003, section 4.1).
//!
//! Will hold: average geodesic distance, the surface Reeb graph, genus reduction by cutting
//! non-separating cycles, protrusion (feature) charts, conformal unwrapping with a harmonic
//! initialisation, virtual boundary with scaffold triangles, stretch optimisation, chart packing.
