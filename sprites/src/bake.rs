//! Baking (to be written).
